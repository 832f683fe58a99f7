//! Jobs: map builds and placement searches. Every job runs on tokio's blocking pool (never on
//! the async runtime's threads), at most `workers` at once behind one semaphore, with at most
//! `queue` more waiting.
//!
//! Single flight: while a map id is being built, every request for it gets the same job; the
//! finished map enters the cache *before* the job leaves the in-flight table, so a request
//! that arrives in between finds the map, never a second build. The requests that wait for a
//! job take the map from the job itself ([`Job::wait_for_map`]), not from the cache, so a
//! cache that evicts it at once (full of other maps) cannot fail them; the job lets go of the
//! map as soon as the last of them has it. Cancellation sets the build's flag, which
//! [`irs_model::radiomap::build`] checks once per grid row.

use super::cache::MapCache;
use crate::app::Error;
use crate::app::identity::{Caller, Owner};
use crate::ids::{JobId, MapId, ScenarioId};
use crate::store::{DataDir, Kind};
use irs_model::placement::{self, Candidate, Placement, Search};
use irs_model::radiomap::{Cancelled, MapKey, Progress, RadioMap, WorkError};
use irs_model::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, VecDeque};
use std::sync::OnceLock;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::{Notify, Semaphore, watch};
use tracing::Instrument;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
}

impl JobState {
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
    pub(crate) fn label(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }
}

/// What kind of job it is: shown as `kind` and labels its metrics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JobKind {
    /// Builds a map.
    Map,
    /// Ranks placement candidates.
    Placement,
}

impl JobKind {
    pub fn as_str(self) -> &'static str {
        match self {
            JobKind::Map => "map",
            JobKind::Placement => "placement",
        }
    }
}

impl Serialize for JobKind {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

/// What a job does.
pub enum Work {
    /// Builds one map (single flight by map id); `delivery` passes it to the waiters.
    Map {
        map_id: MapId,
        key: MapKey,
        delivery: Mutex<MapDelivery>,
    },
    /// Ranks placement candidates; the answer is kept here once the job is done.
    Placement {
        outcome: OnceLock<Arc<PlacementOutcome>>,
    },
}

/// How a map job delivers its built map to the requests waiting for it.
#[derive(Default)]
pub struct MapDelivery {
    /// Requests waiting for the map.
    waiters: usize,
    /// The map, held while waiters remain.
    map: Option<Arc<RadioMap>>,
    /// Set when the build finished: the map for whoever comes late, while anything holds it.
    built: Option<std::sync::Weak<RadioMap>>,
}

/// One request waiting for a map job; the last to go lets the job drop the map.
struct Waiter<'a>(&'a Mutex<MapDelivery>);

impl Drop for Waiter<'_> {
    fn drop(&mut self) {
        let mut h = self.0.lock().expect("job lock");
        h.waiters -= 1;
        if h.waiters == 0 {
            h.map = None;
        }
    }
}

/// A checked placement search, ready to run.
pub struct PlacementSearch {
    pub scenario: Arc<Scenario>,
    pub search: Search,
    /// Its candidates, checked by [`placement::candidates`].
    pub candidates: Vec<Candidate>,
    /// How many of the best to register with their maps.
    pub keep: usize,
}

/// A finished placement search: the answer, and how many of its best candidates were
/// registered with their maps cached (fewer than asked only if the registry refused some).
pub struct PlacementOutcome {
    /// The [`placement::PlacementAnswer`] as JSON: what the API answers, and what a data
    /// directory keeps.
    pub answer: serde_json::Value,
    pub registered: usize,
}

/// One job.
pub struct Job {
    pub id: JobId,
    /// Order of creation, for listings (newest first) and their cursors.
    pub seq: u64,
    /// The token that started it (`None` with authentication off); only it may cancel.
    pub owner: Option<Owner>,
    /// The scenario the job works on (a live job keeps it registered).
    pub scenario_id: ScenarioId,
    pub work: Work,
    pub progress: Arc<Progress>,
    state: watch::Sender<JobState>,
    cancel: Notify,
    times: Mutex<JobTimes>,
    error: Mutex<Option<String>>,
}

#[derive(Debug, Clone, Copy, Default)]
struct JobTimes {
    created: Option<SystemTime>,
    started: Option<SystemTime>,
    finished: Option<SystemTime>,
}

/// A job as the API shows it, and the part of its record that says so: the fields here are
/// the facts a record keeps (read back with serde's derive, so a record from any release that
/// has them is readable); what follows from them (`kind`, `map_id`, `progress` and the links)
/// is added when the view is written (its `Serialize`, below).
#[derive(Debug, Clone, Deserialize)]
pub struct JobView {
    pub job_id: JobId,
    pub scenario_id: ScenarioId,
    /// Map jobs: the key of the map being built (null for placements; its hash is the map id).
    pub key: Option<MapKey>,
    pub state: JobState,
    pub cells_done: usize,
    pub cells_total: usize,
    pub created_at: f64,
    pub started_at: Option<f64>,
    pub finished_at: Option<f64>,
    pub error: Option<String>,
}

impl JobView {
    pub fn kind(&self) -> JobKind {
        match self.key {
            Some(_) => JobKind::Map,
            None => JobKind::Placement,
        }
    }

    /// cells_done / cells_total (0 before the build starts).
    pub fn progress(&self) -> f64 {
        if self.cells_total == 0 {
            0.0
        } else {
            self.cells_done as f64 / self.cells_total as f64
        }
    }
}

/// The API's `Job` (openapi.yaml): the view's fields with what follows from them, in this order.
impl Serialize for JobView {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct as _;
        let map_id = self.key.as_ref().map(MapId::of);
        let result_href = match &map_id {
            Some(map_id) => map_id.href(),
            None => self.job_id.placement_href(),
        };
        let mut job = serializer.serialize_struct("JobView", 15)?;
        job.serialize_field("job_id", &self.job_id)?;
        job.serialize_field("kind", &self.kind())?;
        job.serialize_field("scenario_id", &self.scenario_id)?;
        job.serialize_field("map_id", &map_id)?;
        job.serialize_field("key", &self.key)?;
        job.serialize_field("state", &self.state)?;
        job.serialize_field("cells_done", &self.cells_done)?;
        job.serialize_field("cells_total", &self.cells_total)?;
        job.serialize_field("progress", &self.progress())?;
        job.serialize_field("created_at", &self.created_at)?;
        job.serialize_field("started_at", &self.started_at)?;
        job.serialize_field("finished_at", &self.finished_at)?;
        job.serialize_field("error", &self.error)?;
        job.serialize_field("href", &self.job_id.href())?;
        // Where the result is read once the job is done: the map, or the placement answer.
        job.serialize_field("result_href", &result_href)?;
        job.end()
    }
}

/// A job as the data directory (`serve --data-dir`, finished jobs) and Redis (a cluster's map
/// builds, while they run and after) keep it: its view, and what it takes to list, authorise
/// and, for a placement, answer it again.
#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct JobRecord {
    #[serde(flatten)]
    pub view: JobView,
    pub seq: u64,
    /// The owner's digest (never the token).
    pub owner: Option<String>,
    /// Placement jobs that finished: the answer and how many candidates were registered.
    pub placement: Option<(serde_json::Value, usize)>,
}

impl JobRecord {
    /// A map job not started yet, as the replica that takes a request records it.
    pub(crate) fn queued(key: &MapKey, owner: Option<&Owner>) -> JobRecord {
        JobRecord {
            view: JobView {
                job_id: JobId::random(),
                scenario_id: ScenarioId::of_key(key),
                key: Some(key.clone()),
                state: JobState::Queued,
                cells_done: 0,
                cells_total: 0,
                created_at: unix(Some(SystemTime::now())).unwrap_or(0.0),
                started_at: None,
                finished_at: None,
                error: None,
            },
            seq: 0,
            owner: owner.map(|o| o.to_string()),
            placement: None,
        }
    }

    /// The owner, as [`Caller::may_touch`] takes it.
    pub(crate) fn owner(&self) -> Option<Owner> {
        self.owner.clone().map(Owner::from_digest)
    }
}

fn from_unix(t: f64) -> Option<SystemTime> {
    (t.is_finite() && t >= 0.0).then(|| UNIX_EPOCH + Duration::from_secs_f64(t))
}

fn unix(t: Option<SystemTime>) -> Option<f64> {
    t.map(|t| {
        t.duration_since(UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64())
    })
}

impl Job {
    pub fn state(&self) -> JobState {
        *self.state.borrow()
    }

    pub fn kind(&self) -> JobKind {
        match &self.work {
            Work::Map { .. } => JobKind::Map,
            Work::Placement { .. } => JobKind::Placement,
        }
    }

    /// The map a map job builds.
    pub fn map_id(&self) -> Option<&MapId> {
        match &self.work {
            Work::Map { map_id, .. } => Some(map_id),
            Work::Placement { .. } => None,
        }
    }

    /// Waits for a map job and takes its map: `None` if the build failed or was cancelled.
    pub async fn wait_for_map(&self) -> Option<Arc<RadioMap>> {
        let Work::Map { delivery, .. } = &self.work else {
            return None;
        };
        {
            let mut h = delivery.lock().expect("job lock");
            if let Some(built) = &h.built {
                return built.upgrade();
            }
            h.waiters += 1;
        }
        // Counted out on drop too: a waiter whose client left must not pin the map.
        let waiter = Waiter(delivery);
        self.finished().await;
        let map = {
            let h = delivery.lock().expect("job lock");
            h.map.clone().or_else(|| h.built.as_ref()?.upgrade())
        };
        drop(waiter);
        map
    }

    /// Hands the built map to the waiters (held only if there are some).
    fn deliver(&self, map: &Arc<RadioMap>) {
        if let Work::Map { delivery, .. } = &self.work {
            let mut h = delivery.lock().expect("job lock");
            h.built = Some(Arc::downgrade(map));
            if h.waiters > 0 {
                h.map = Some(map.clone());
            }
        }
    }

    /// A placement job's outcome, once it is done.
    pub fn placement(&self) -> Option<Arc<PlacementOutcome>> {
        match &self.work {
            Work::Placement { outcome } => outcome.get().cloned(),
            Work::Map { .. } => None,
        }
    }

    pub fn view(&self) -> JobView {
        let times = *self.times.lock().expect("job lock");
        JobView {
            job_id: self.id.clone(),
            scenario_id: self.scenario_id.clone(),
            key: match &self.work {
                Work::Map { key, .. } => Some(key.clone()),
                Work::Placement { .. } => None,
            },
            state: self.state(),
            cells_done: self.progress.cells_done(),
            cells_total: self.progress.cells_total(),
            created_at: unix(times.created).unwrap_or(0.0),
            started_at: unix(times.started),
            finished_at: unix(times.finished),
            error: self.error.lock().expect("job lock").clone(),
        }
    }

    /// The record a data directory keeps of a finished job (and Redis of a cluster's build).
    pub(crate) fn record(&self) -> JobRecord {
        JobRecord {
            view: self.view(),
            seq: self.seq,
            owner: self.owner.as_ref().map(|o| o.to_string()),
            placement: self
                .placement()
                .map(|outcome| (outcome.answer.clone(), outcome.registered)),
        }
    }

    /// A finished job again, from its record; `None` for a record that is not of a finished
    /// job (the store only writes finished ones) or whose map key does not match its kind.
    fn restore(record: JobRecord) -> Option<Job> {
        let JobRecord {
            view,
            seq,
            owner,
            placement,
        } = record;
        if !view.state.is_terminal() {
            return None;
        }
        let work = match (view.key, placement) {
            (Some(key), None) => Work::Map {
                map_id: MapId::of(&key),
                key,
                delivery: Mutex::new(MapDelivery::default()),
            },
            (None, placement) => {
                let outcome = OnceLock::new();
                if let Some((answer, registered)) = placement {
                    let _ = outcome.set(Arc::new(PlacementOutcome { answer, registered }));
                }
                Work::Placement { outcome }
            }
            (Some(_), Some(_)) => return None,
        };
        let progress = Progress::default();
        progress.start(view.cells_total);
        progress.advance(view.cells_done.min(view.cells_total));
        let (state, _) = watch::channel(view.state);
        Some(Job {
            id: view.job_id,
            seq,
            owner: owner.map(Owner::from_digest),
            scenario_id: view.scenario_id,
            work,
            progress: Arc::new(progress),
            state,
            cancel: Notify::new(),
            times: Mutex::new(JobTimes {
                created: from_unix(view.created_at),
                started: view.started_at.and_then(from_unix),
                finished: view.finished_at.and_then(from_unix),
            }),
            error: Mutex::new(view.error),
        })
    }

    /// Waits until the job ends.
    pub async fn finished(&self) -> JobState {
        let mut rx = self.state.subscribe();
        // The guard `wait_for` returns borrows `rx`; copy the state out before `rx` drops.
        #[allow(clippy::let_and_return)]
        let state = rx
            .wait_for(|s| s.is_terminal())
            .await
            .map(|s| *s)
            .unwrap_or(JobState::Failed);
        state
    }

    fn set_state(&self, next: JobState) {
        let previous = self.state.send_replace(next);
        if previous != next {
            metrics::gauge!("irs_jobs", "state" => previous.label()).decrement(1.0);
            metrics::gauge!("irs_jobs", "state" => next.label()).increment(1.0);
        }
        let mut times = self.times.lock().expect("job lock");
        match next {
            JobState::Running => times.started = Some(SystemTime::now()),
            s if s.is_terminal() => times.finished = Some(SystemTime::now()),
            _ => {}
        }
    }
}

/// The outcome of asking for a map.
pub enum MapRequestOutcome {
    Ready(Arc<RadioMap>),
    Building(Arc<Job>),
}

pub struct Jobs {
    next_seq: AtomicU64,
    workers: Arc<Semaphore>,
    queue_limit: usize,
    queued: Arc<AtomicUsize>,
    history_limit: usize,
    by_id: Mutex<HashMap<JobId, Arc<Job>>>,
    finished_order: Mutex<VecDeque<JobId>>,
    in_flight: tokio::sync::Mutex<HashMap<MapId, Arc<Job>>>,
    /// With `--data-dir`: finished jobs are recorded there, and forgotten there too.
    disk: Option<Arc<DataDir>>,
}

impl Jobs {
    pub fn new(
        workers: usize,
        queue_limit: usize,
        history_limit: usize,
        disk: Option<Arc<DataDir>>,
    ) -> Self {
        Jobs {
            next_seq: AtomicU64::new(0),
            workers: Arc::new(Semaphore::new(workers)),
            queue_limit,
            queued: Arc::new(AtomicUsize::new(0)),
            history_limit,
            by_id: Mutex::new(HashMap::new()),
            finished_order: Mutex::new(VecDeque::new()),
            in_flight: tokio::sync::Mutex::new(HashMap::new()),
            disk,
        }
    }

    /// Takes back the finished jobs the data directory recorded (oldest first, the newest
    /// `history_limit` kept); new jobs are numbered after them. Returns how many.
    pub fn restore(&self) -> usize {
        let Some(disk) = &self.disk else { return 0 };
        let mut jobs: Vec<Job> = disk
            .load_json::<JobRecord>(Kind::Job)
            .into_iter()
            .filter_map(|(file_id, record)| {
                (record.view.job_id.as_str() == file_id)
                    .then_some(record)
                    .and_then(Job::restore)
            })
            .collect();
        jobs.sort_by_key(|job| job.seq);
        let surplus = jobs.len().saturating_sub(self.history_limit);
        for old in jobs.drain(..surplus) {
            disk.remove_json(Kind::Job, old.id.as_str());
        }
        let next = jobs.last().map_or(0, |job| job.seq + 1);
        self.next_seq.fetch_max(next, Ordering::Relaxed);
        let mut by_id = self.by_id.lock().expect("jobs lock");
        let mut order = self.finished_order.lock().expect("jobs lock");
        let restored = jobs.len();
        for job in jobs {
            order.push_back(job.id.clone());
            by_id.insert(job.id.clone(), Arc::new(job));
        }
        restored
    }

    pub fn get(&self, id: &JobId) -> Option<Arc<Job>> {
        self.by_id.lock().expect("jobs lock").get(id).cloned()
    }

    /// The job building `map_id`, if one is queued or running.
    pub async fn building(&self, map_id: &MapId) -> Option<Arc<Job>> {
        self.in_flight.lock().await.get(map_id).cloned()
    }

    /// Cancels every queued and running job (shutdown); returns their ids.
    pub fn cancel_all(&self) -> Vec<JobId> {
        self.live()
            .into_iter()
            .map(|job| {
                job.progress.cancel();
                job.cancel.notify_one();
                job.id.clone()
            })
            .collect()
    }

    /// The jobs that are queued or running.
    pub fn live(&self) -> Vec<Arc<Job>> {
        self.by_id
            .lock()
            .expect("jobs lock")
            .values()
            .filter(|j| !j.state().is_terminal())
            .cloned()
            .collect()
    }

    /// The jobs `caller` may see, newest first, with their sequence numbers (for cursors).
    pub fn list(&self, caller: &Caller) -> Vec<(u64, JobView)> {
        let mut all: Vec<(u64, JobView)> = self
            .by_id
            .lock()
            .expect("jobs lock")
            .values()
            .filter(|j| caller.may_touch(j.owner.as_ref()))
            .map(|j| (j.seq, j.view()))
            .collect();
        all.sort_by_key(|(seq, _)| std::cmp::Reverse(*seq));
        all
    }

    /// The map if cached, else the job building it (started now unless one is in flight).
    pub async fn request(
        self: &Arc<Self>,
        cache: &MapCache,
        scenario: Arc<Scenario>,
        key: MapKey,
        owner: Option<Owner>,
    ) -> Result<MapRequestOutcome, Error> {
        let map_id = MapId::of(&key);
        let mut in_flight = self.in_flight.lock().await;
        if let Some(map) = cache.get(&map_id).await {
            return Ok(MapRequestOutcome::Ready(map));
        }
        if let Some(job) = in_flight.get(&map_id) {
            return Ok(MapRequestOutcome::Building(job.clone()));
        }
        if self.queued.load(Ordering::SeqCst) >= self.queue_limit + self.workers.available_permits()
        {
            return Err(Error::QueueFull {
                limit: self.queue_limit,
            });
        }
        let job = self.admit_map(JobId::random(), &key, owner);
        in_flight.insert(map_id.clone(), job.clone());
        let span = tracing::info_span!("job", job_id = %job.id, map_id = %map_id, scenario_id = %key.scenario_id);
        let progress = job.progress.clone();
        let cache = cache.clone();
        let work =
            move || irs_answers::map::build(&scenario, &key, &progress).map_err(WorkError::from);
        let finish = move |job: Arc<Job>, map: RadioMap| async move {
            let map = Arc::new(map);
            job.deliver(&map);
            cache.insert(map_id, map).await;
        };
        crate::tasks::spawn(self.clone().run(job.clone(), work, finish).instrument(span));
        Ok(MapRequestOutcome::Building(job))
    }

    /// Builds a map another replica (or this one) queued in the cluster's stream, as the local
    /// job `job_id` (so this replica shows its live progress). When it is done, `publish`
    /// gets the map before the job says `done`, then the map enters `cache`. Counted in
    /// `irs_map_builds_total`, which in a cluster counts builds, not requests.
    pub(crate) fn build_shared<P, Fut>(
        self: &Arc<Self>,
        job_id: JobId,
        scenario: Arc<Scenario>,
        key: MapKey,
        owner: Option<Owner>,
        cache: &MapCache,
        publish: P,
    ) -> Arc<Job>
    where
        P: FnOnce(Arc<RadioMap>) -> Fut + Send + 'static,
        Fut: std::future::Future<Output = Result<(), String>> + Send,
    {
        let map_id = MapId::of(&key);
        let job = self.admit_map(job_id, &key, owner);
        let span = tracing::info_span!("job", job_id = %job.id, map_id = %map_id, scenario_id = %key.scenario_id, shared = true);
        let progress = job.progress.clone();
        let cache = cache.clone();
        let work =
            move || irs_answers::map::build(&scenario, &key, &progress).map_err(WorkError::from);
        let built_id = map_id.clone();
        let finish = move |job: Arc<Job>, map: RadioMap| async move {
            let map = Arc::new(map);
            job.deliver(&map);
            if let Err(e) = publish(map.clone()).await {
                tracing::warn!(error = %e, "built map not shared: other replicas will build it again");
            }
            cache.insert(built_id, map).await;
        };
        let runner = self.clone();
        let handle = job.clone();
        crate::tasks::spawn(
            async move {
                runner.in_flight.lock().await.insert(map_id, handle.clone());
                runner.run(handle, work, finish).await;
            }
            .instrument(span),
        );
        job
    }

    /// Asks a local job to stop (a cancellation that came through the shared store).
    pub(crate) fn cancel_local(&self, job: &Job) {
        job.progress.cancel();
        job.cancel.notify_one();
    }

    /// Workers free now (the cluster's builder reads the stream only when one is).
    pub(crate) fn free_workers(&self) -> usize {
        self.workers.available_permits()
    }

    /// Starts a placement search as a job (503 when the queue is full). When it is done, the
    /// best `keep` candidates' scenarios go to `register` and their maps into `cache`, so the
    /// answer's map ids answer path queries at once; then the answer is kept in the job.
    pub fn place(
        self: &Arc<Self>,
        cache: &MapCache,
        search: PlacementSearch,
        owner: Option<Owner>,
        register: impl Fn(Scenario) -> bool + Send + 'static,
    ) -> Result<Arc<Job>, Error> {
        let PlacementSearch {
            scenario,
            search,
            candidates,
            keep,
        } = search;
        if self.queued.load(Ordering::SeqCst) >= self.queue_limit + self.workers.available_permits()
        {
            return Err(Error::QueueFull {
                limit: self.queue_limit,
            });
        }
        let job = self.admit(
            ScenarioId::of(&scenario),
            owner,
            Work::Placement {
                outcome: OnceLock::new(),
            },
        );
        metrics::counter!("irs_placements_total").increment(1);
        let span = tracing::info_span!("job", job_id = %job.id, kind = "placement", scenario_id = %job.scenario_id);
        let progress = job.progress.clone();
        let work = move || -> Result<(Placement, Vec<RadioMap>), WorkError> {
            let placement = placement::rank_candidates(
                &scenario,
                &search,
                candidates,
                &irs_answers::map::ContentIds,
                &progress,
            )?;
            let phases = placement.answer.phases;
            // The best candidates' maps, built now so their ids answer at once (gain maps of
            // the search's floor: milliseconds each).
            let maps = placement
                .scenarios
                .iter()
                .take(keep)
                .map(|s| {
                    if progress.is_cancelled() {
                        return Err(Cancelled.into());
                    }
                    let key = MapKey::gain(ScenarioId::of(s).as_str(), s, phases)?;
                    Ok(irs_answers::map::build(s, &key, &Progress::default())?)
                })
                .collect::<Result<Vec<_>, WorkError>>()?;
            Ok((placement, maps))
        };
        let cache = cache.clone();
        let finish = move |job: Arc<Job>, (placement, maps): (Placement, Vec<RadioMap>)| async move {
            let mut registered = 0;
            for (scenario, map) in placement.scenarios.into_iter().zip(maps) {
                if register(scenario) {
                    cache.insert(MapId::of_map(&map), Arc::new(map)).await;
                    registered += 1;
                }
            }
            if let Work::Placement { outcome } = &job.work {
                let _ = outcome.set(Arc::new(PlacementOutcome {
                    answer: serde_json::to_value(&placement.answer).expect("answers serialise"),
                    registered,
                }));
            }
        };
        crate::tasks::spawn(self.clone().run(job.clone(), work, finish).instrument(span));
        Ok(job)
    }

    /// Creates a queued job and records it.
    fn admit(&self, scenario_id: ScenarioId, owner: Option<Owner>, work: Work) -> Arc<Job> {
        self.admit_as(JobId::random(), scenario_id, owner, work)
    }

    /// A map build admitted as job `id`, counted in `irs_map_builds_total`.
    fn admit_map(&self, id: JobId, key: &MapKey, owner: Option<Owner>) -> Arc<Job> {
        metrics::counter!("irs_map_builds_total", "kind" => key.kind.to_string()).increment(1);
        self.admit_as(
            id,
            ScenarioId::of_key(key),
            owner,
            Work::Map {
                map_id: MapId::of(key),
                key: key.clone(),
                delivery: Mutex::new(MapDelivery::default()),
            },
        )
    }

    /// [`Jobs::admit`] under a given id (a cluster job keeps the id its record has).
    fn admit_as(
        &self,
        id: JobId,
        scenario_id: ScenarioId,
        owner: Option<Owner>,
        work: Work,
    ) -> Arc<Job> {
        let (state, _) = watch::channel(JobState::Queued);
        let job = Arc::new(Job {
            id,
            seq: self.next_seq.fetch_add(1, Ordering::Relaxed),
            owner,
            scenario_id,
            work,
            progress: Arc::new(Progress::default()),
            state,
            cancel: Notify::new(),
            times: Mutex::new(JobTimes {
                created: Some(SystemTime::now()),
                ..Default::default()
            }),
            error: Mutex::new(None),
        });
        metrics::gauge!("irs_jobs", "state" => "queued").increment(1.0);
        self.by_id
            .lock()
            .expect("jobs lock")
            .insert(job.id.clone(), job.clone());
        self.queued.fetch_add(1, Ordering::SeqCst);
        job
    }

    /// Runs `work` on the blocking pool once a worker is free, then `finish` with its result.
    async fn run<T, W, F, Fut>(self: Arc<Self>, job: Arc<Job>, work: W, finish: F)
    where
        T: Send + 'static,
        W: FnOnce() -> Result<T, WorkError> + Send + 'static,
        F: FnOnce(Arc<Job>, T) -> Fut,
        Fut: std::future::Future<Output = ()>,
    {
        let queued_at = Instant::now();
        let permit = tokio::select! {
            permit = self.workers.clone().acquire_owned() => permit.ok(),
            _ = job.cancel.notified() => None,
        };
        self.queued.fetch_sub(1, Ordering::SeqCst);
        let Some(permit) = permit.filter(|_| !job.progress.is_cancelled()) else {
            job.set_state(JobState::Cancelled);
            tracing::info!("cancelled while queued");
            self.retire(&job).await;
            return;
        };
        job.set_state(JobState::Running);
        let waited = queued_at.elapsed().as_secs_f64();
        tracing::info!(queued_s = waited, "job started");
        let started = Instant::now();
        let result = crate::tasks::spawn_blocking(|| {
            // The job's own sequential parts yield to the runtime as the pools' threads do. The
            // blocking pool runs nothing latency-bound (builds, map encoding, disk writes), so
            // a thread that stays lowered for its next task costs nothing.
            super::priority::lower_this_thread();
            work()
        })
        .await;
        drop(permit);
        let seconds = started.elapsed().as_secs_f64();
        match result {
            Ok(Ok(output)) => {
                metrics::histogram!("irs_job_seconds", "kind" => job.kind().as_str())
                    .record(seconds);
                finish(job.clone(), output).await;
                job.set_state(JobState::Done);
                tracing::info!(run_s = seconds, "job done");
            }
            Ok(Err(WorkError::Cancelled(Cancelled))) => {
                job.set_state(JobState::Cancelled);
                tracing::info!(
                    run_s = seconds,
                    cells_done = job.progress.cells_done(),
                    "job cancelled"
                );
            }
            Ok(Err(WorkError::Invalid(e))) => {
                // Checked before the job was created; kept for completeness.
                *job.error.lock().expect("job lock") = Some(e.to_string());
                job.set_state(JobState::Failed);
                tracing::error!(error = %e, "job failed");
            }
            Err(panic) => {
                *job.error.lock().expect("job lock") = Some(format!("the job panicked: {panic}"));
                job.set_state(JobState::Failed);
                tracing::error!(error = %panic, "job panicked");
            }
        }
        self.retire(&job).await;
    }

    /// Removes a finished job from the in-flight table and forgets the oldest finished jobs
    /// beyond the history limit.
    async fn retire(&self, job: &Arc<Job>) {
        if let Some(map_id) = job.map_id() {
            self.in_flight.lock().await.remove(map_id);
        }
        if let Some(disk) = self.disk.clone() {
            let (id, record) = (job.id.clone(), job.record());
            // A small file, but flushed to disk: off the async threads.
            let _ = crate::tasks::spawn_blocking(move || {
                disk.save_json(Kind::Job, id.as_str(), &record)
            })
            .await;
        }
        let mut order = self.finished_order.lock().expect("jobs lock");
        order.push_back(job.id.clone());
        while order.len() > self.history_limit {
            if let Some(old) = order.pop_front() {
                self.by_id.lock().expect("jobs lock").remove(&old);
                if let Some(disk) = &self.disk {
                    disk.remove_json(Kind::Job, old.as_str());
                }
            }
        }
    }

    /// Cancels a queued or running job; a job of another token is not found (404).
    pub fn cancel(&self, id: &JobId, caller: &Caller) -> Result<Arc<Job>, Error> {
        let job = self
            .get(id)
            .filter(|job| caller.may_touch(job.owner.as_ref()))
            .ok_or_else(|| Error::not_found("job", id))?;
        let state = job.state();
        if state.is_terminal() {
            return Err(Error::JobFinished {
                job_id: id.clone(),
                state: state.label(),
            });
        }
        job.progress.cancel();
        job.cancel.notify_one();
        Ok(job)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A finished map job's record as the data directory and Redis hold it.
    const MAP_RECORD: &str = r#"{"job_id":"0123456789abcdef0123456789abcdef","seq":7,"owner":"d1gest","scenario_id":"5c3na410","key":{"scenario_id":"5c3na410","kind":"gain","phases":"continuous","access":null,"solver":null},"state":"done","cells_done":40,"cells_total":40,"created_at":1700000000.25,"started_at":1700000001.5,"finished_at":1700000002.75,"error":null,"placement":null}"#;

    /// A finished placement job's record.
    const PLACEMENT_RECORD: &str = r#"{"job_id":"fedcba9876543210fedcba9876543210","seq":8,"owner":null,"scenario_id":"5c3na410","key":null,"state":"failed","cells_done":3,"cells_total":12,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":null,"error":"it broke","placement":[{"best":1},2]}"#;

    /// A record reads back as the record it was, and carries every field of today's format
    /// (so the release before this one reads it too).
    fn round_trip(record: &JobRecord, today: &str) {
        let written = serde_json::to_value(record).unwrap();
        let again: JobRecord = serde_json::from_value(written.clone()).unwrap();
        assert_eq!(serde_json::to_value(&again).unwrap(), written);
        let today: serde_json::Value = serde_json::from_str(today).unwrap();
        for (field, value) in today.as_object().unwrap() {
            assert_eq!(&written[field], value, "{field}");
        }
    }

    #[test]
    fn records_of_today_are_read_and_shown_as_before() {
        let map: JobRecord = serde_json::from_str(MAP_RECORD).unwrap();
        let map_id = irs_answers::map::map_id(map.view.key.as_ref().unwrap());
        let expected = format!(
            r#"{{"job_id":"0123456789abcdef0123456789abcdef","kind":"map","scenario_id":"5c3na410","map_id":"{map_id}","key":{{"scenario_id":"5c3na410","kind":"gain","phases":"continuous","access":null,"solver":null}},"state":"done","cells_done":40,"cells_total":40,"progress":1.0,"created_at":1700000000.25,"started_at":1700000001.5,"finished_at":1700000002.75,"error":null,"href":"/v1/jobs/0123456789abcdef0123456789abcdef","result_href":"/v1/maps/{map_id}"}}"#
        );
        assert_eq!(serde_json::to_string(&map.view).unwrap(), expected);
        let job = Job::restore(map).unwrap();
        assert_eq!(serde_json::to_string(&job.view()).unwrap(), expected);
        round_trip(&job.record(), MAP_RECORD);

        let placement: JobRecord = serde_json::from_str(PLACEMENT_RECORD).unwrap();
        let expected = r#"{"job_id":"fedcba9876543210fedcba9876543210","kind":"placement","scenario_id":"5c3na410","map_id":null,"key":null,"state":"failed","cells_done":3,"cells_total":12,"progress":0.25,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":null,"error":"it broke","href":"/v1/jobs/fedcba9876543210fedcba9876543210","result_href":"/v1/placements/fedcba9876543210fedcba9876543210"}"#;
        assert_eq!(serde_json::to_string(&placement.view).unwrap(), expected);
        let job = Job::restore(placement).unwrap();
        assert_eq!(serde_json::to_string(&job.view()).unwrap(), expected);
        round_trip(&job.record(), PLACEMENT_RECORD);
    }
}
