//! Map-building jobs: every build runs on tokio's blocking pool (never on the async runtime's
//! threads), at most `workers` at once behind a semaphore, with at most `queue` more waiting.
//!
//! Single flight: while a map id is being built, every request for it gets the same job; the
//! finished map enters the cache *before* the job leaves the in-flight table, so a request
//! that arrives in between finds the map, never a second build. Cancellation sets the build's
//! flag, which [`crate::radiomap::build`] checks once per grid row.

use super::cache::MapCache;
use super::errors::ApiError;
use crate::radiomap::{self, Cancelled, MapKey, Progress, RadioMap};
use crate::scenario::Scenario;
use serde::Serialize;
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime, UNIX_EPOCH};
use tokio::sync::{Notify, Semaphore, watch};
use tracing::Instrument;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
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
    fn label(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }
}

/// One map build.
pub struct Job {
    pub id: String,
    pub map_id: String,
    pub key: MapKey,
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

/// A job as the API shows it.
#[derive(Debug, Clone, Serialize)]
pub struct JobView {
    pub job_id: String,
    pub map_id: String,
    pub key: MapKey,
    pub state: JobState,
    pub cells_done: usize,
    pub cells_total: usize,
    /// cells_done / cells_total (0 before the build starts).
    pub progress: f64,
    pub created_at: f64,
    pub started_at: Option<f64>,
    pub finished_at: Option<f64>,
    pub error: Option<String>,
    pub href: String,
    pub map_href: String,
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

    pub fn view(&self) -> JobView {
        let times = *self.times.lock().expect("job lock");
        let (done, total) = (self.progress.cells_done(), self.progress.cells_total());
        JobView {
            job_id: self.id.clone(),
            map_id: self.map_id.clone(),
            key: self.key.clone(),
            state: self.state(),
            cells_done: done,
            cells_total: total,
            progress: if total == 0 {
                0.0
            } else {
                done as f64 / total as f64
            },
            created_at: unix(times.created).unwrap_or(0.0),
            started_at: unix(times.started),
            finished_at: unix(times.finished),
            error: self.error.lock().expect("job lock").clone(),
            href: format!("/v1/jobs/{}", self.id),
            map_href: format!("/v1/maps/{}", self.map_id),
        }
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
    workers: Arc<Semaphore>,
    queue_limit: usize,
    queued: Arc<AtomicUsize>,
    history_limit: usize,
    by_id: Mutex<HashMap<String, Arc<Job>>>,
    finished_order: Mutex<VecDeque<String>>,
    in_flight: tokio::sync::Mutex<HashMap<String, Arc<Job>>>,
}

impl Jobs {
    pub fn new(workers: usize, queue_limit: usize, history_limit: usize) -> Self {
        Jobs {
            workers: Arc::new(Semaphore::new(workers)),
            queue_limit,
            queued: Arc::new(AtomicUsize::new(0)),
            history_limit,
            by_id: Mutex::new(HashMap::new()),
            finished_order: Mutex::new(VecDeque::new()),
            in_flight: tokio::sync::Mutex::new(HashMap::new()),
        }
    }

    pub fn get(&self, id: &str) -> Option<Arc<Job>> {
        self.by_id.lock().expect("jobs lock").get(id).cloned()
    }

    /// The job building `map_id`, if one is queued or running.
    pub async fn building(&self, map_id: &str) -> Option<Arc<Job>> {
        self.in_flight.lock().await.get(map_id).cloned()
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

    pub fn list(&self) -> Vec<JobView> {
        let mut all: Vec<JobView> = self
            .by_id
            .lock()
            .expect("jobs lock")
            .values()
            .map(|j| j.view())
            .collect();
        all.sort_by(|a, b| b.created_at.total_cmp(&a.created_at));
        all
    }

    /// The map if cached, else the job building it (started now unless one is in flight).
    pub async fn request(
        self: &Arc<Self>,
        cache: &MapCache,
        scenario: Arc<Scenario>,
        key: MapKey,
    ) -> Result<MapRequestOutcome, ApiError> {
        let map_id = key.id();
        let mut in_flight = self.in_flight.lock().await;
        if let Some(map) = cache.get(&map_id).await {
            return Ok(MapRequestOutcome::Ready(map));
        }
        if let Some(job) = in_flight.get(&map_id) {
            return Ok(MapRequestOutcome::Building(job.clone()));
        }
        if self.queued.load(Ordering::SeqCst) >= self.queue_limit + self.workers.available_permits()
        {
            return Err(ApiError::queue_full(self.queue_limit));
        }
        let (state, _) = watch::channel(JobState::Queued);
        let job = Arc::new(Job {
            id: uuid::Uuid::new_v4().simple().to_string(),
            map_id: map_id.clone(),
            key: key.clone(),
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
        metrics::counter!("irs_map_builds_total", "kind" => format!("{:?}", key.kind).to_lowercase()).increment(1);
        self.by_id
            .lock()
            .expect("jobs lock")
            .insert(job.id.clone(), job.clone());
        in_flight.insert(map_id, job.clone());
        self.queued.fetch_add(1, Ordering::SeqCst);
        let span = tracing::info_span!("job", job_id = %job.id, map_id = %job.map_id, scenario_id = %key.scenario_id);
        tokio::spawn(
            self.clone()
                .run(job.clone(), scenario, cache.clone())
                .instrument(span),
        );
        Ok(MapRequestOutcome::Building(job))
    }

    async fn run(self: Arc<Self>, job: Arc<Job>, scenario: Arc<Scenario>, cache: MapCache) {
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
        tracing::info!(queued_s = waited, "build started");
        let progress = job.progress.clone();
        let key = job.key.clone();
        let started = Instant::now();
        let result =
            tokio::task::spawn_blocking(move || radiomap::build(&scenario, &key, &progress)).await;
        drop(permit);
        let seconds = started.elapsed().as_secs_f64();
        match result {
            Ok(Ok(map)) => {
                metrics::histogram!("irs_map_build_seconds").record(seconds);
                cache.insert(job.map_id.clone(), Arc::new(map)).await;
                job.set_state(JobState::Done);
                tracing::info!(build_s = seconds, "build done");
            }
            Ok(Err(Cancelled)) => {
                job.set_state(JobState::Cancelled);
                tracing::info!(
                    build_s = seconds,
                    cells_done = job.progress.cells_done(),
                    "build cancelled"
                );
            }
            Err(panic) => {
                *job.error.lock().expect("job lock") = Some(format!("the build panicked: {panic}"));
                job.set_state(JobState::Failed);
                tracing::error!(error = %panic, "build panicked");
            }
        }
        self.retire(&job).await;
    }

    /// Removes a finished job from the in-flight table and forgets the oldest finished jobs
    /// beyond the history limit.
    async fn retire(&self, job: &Arc<Job>) {
        self.in_flight.lock().await.remove(&job.map_id);
        let mut order = self.finished_order.lock().expect("jobs lock");
        order.push_back(job.id.clone());
        while order.len() > self.history_limit {
            if let Some(old) = order.pop_front() {
                self.by_id.lock().expect("jobs lock").remove(&old);
            }
        }
    }

    /// Cancels a queued or running job.
    pub fn cancel(&self, id: &str) -> Result<Arc<Job>, ApiError> {
        let job = self.get(id).ok_or_else(|| ApiError::not_found("job", id))?;
        let state = job.state();
        if state.is_terminal() {
            return Err(ApiError::job_finished(id, state.label()));
        }
        job.progress.cancel();
        job.cancel.notify_one();
        Ok(job)
    }
}
