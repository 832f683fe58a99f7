//! Jobs: map builds, placement searches, Monte Carlo checks and fleet plans. Every job runs on tokio's blocking pool (never on
//! the async runtime's threads), at most `workers` at once behind one semaphore, with at most
//! `queue` more waiting. This file holds the table of jobs (admission, running, history,
//! listing, cancellation); [`job`] one job, [`record`] its view and record, [`maps`] the map
//! builds' single flight, [`placements`] the placement searches, [`answers`] the jobs with
//! one JSON answer (Monte Carlo checks of paths, fleet plans).

mod answers;
mod job;
mod maps;
mod placements;
mod record;

pub use answers::{AnswerKind, SYNC_CHECK_S};
use job::JobTimes;
pub use job::{Job, JobState, Withdrawn, Work};
pub use maps::MapRequestOutcome;
pub(crate) use maps::SharedBuild;
pub use placements::{PlacementOutcome, PlacementSearch};
pub(crate) use record::{JobRecord, JobView};

use crate::app::Error;
use crate::app::identity::{Caller, Owner, Owners};
use crate::ids::{JobId, MapId, ScenarioId};
use crate::store::Store;
use crate::store::{DataDir, Kind};
use irs_model::radiomap::{Cancelled, Progress, WorkError};
use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Instant, SystemTime};
use tokio::sync::{Notify, Semaphore, watch};

pub struct Jobs {
    next_seq: AtomicU64,
    workers: Arc<Semaphore>,
    /// How many workers there are (`workers` counts the free ones).
    worker_count: usize,
    queue_limit: usize,
    queued: Arc<AtomicUsize>,
    history: Mutex<History>,
    by_id: Mutex<HashMap<JobId, Arc<Job>>>,
    in_flight: tokio::sync::Mutex<HashMap<MapId, Arc<Job>>>,
    /// With `--data-dir`: finished jobs are recorded there, and forgotten there too.
    disk: Option<Arc<DataDir>>,
    /// The claims on maps: a build that ends without its map leaves no claim behind.
    store: Arc<dyn Store>,
}

impl Jobs {
    /// `history_limit` finished jobs are kept, their answers weighing at most
    /// `history_bytes` (the newest one is kept whatever it weighs).
    pub fn new(
        workers: usize,
        queue_limit: usize,
        history_limit: usize,
        history_bytes: u64,
        disk: Option<Arc<DataDir>>,
        store: Arc<dyn Store>,
    ) -> Self {
        Jobs {
            next_seq: AtomicU64::new(0),
            workers: Arc::new(Semaphore::new(workers)),
            worker_count: workers,
            queue_limit,
            queued: Arc::new(AtomicUsize::new(0)),
            history: Mutex::new(History {
                order: VecDeque::new(),
                bytes: 0,
                limit: history_limit,
                budget: history_bytes,
            }),
            by_id: Mutex::new(HashMap::new()),
            in_flight: tokio::sync::Mutex::new(HashMap::new()),
            disk,
            store,
        }
    }

    /// Takes back the finished jobs the data directory recorded (oldest first, the newest
    /// within the history's count and bytes kept); new jobs are numbered after them. Returns
    /// how many, and the records of the map builds a shutdown interrupted, to resume
    /// ([`Jobs::resume`]).
    pub fn restore(&self) -> (usize, Vec<JobRecord>) {
        let Some(disk) = &self.disk else {
            return (0, Vec::new());
        };
        let (finished, interrupted): (Vec<JobRecord>, Vec<JobRecord>) = disk
            .load_json::<JobRecord>(Kind::Job)
            .into_iter()
            .filter(|(file_id, record)| record.view.job_id.as_str() == file_id)
            .map(|(_, record)| record)
            .partition(|record| record.view.state.is_terminal());
        let interrupted = interrupted
            .into_iter()
            .filter(|record| record.view.key.is_some())
            .collect();
        let mut jobs: Vec<Job> = finished.into_iter().filter_map(Job::restore).collect();
        jobs.sort_by_key(|job| job.seq);
        let next = jobs.last().map_or(0, |job| job.seq + 1);
        self.next_seq.fetch_max(next, Ordering::Relaxed);
        let mut by_id = self.by_id.lock().expect("jobs lock");
        let mut history = self.history.lock().expect("jobs lock");
        for job in jobs {
            history.push(&job);
            by_id.insert(job.id.clone(), Arc::new(job));
        }
        for old in history.trim() {
            by_id.remove(&old);
            disk.remove_json(Kind::Job, old.as_str());
        }
        (history.order.len(), interrupted)
    }

    /// Records a job that ended before it could start again (an interrupted build settled at
    /// start-up): on disk, and in the history like any finished job.
    pub fn settle(&self, record: JobRecord) {
        if let Some(disk) = &self.disk {
            disk.save_json(Kind::Job, record.view.job_id.as_str(), &record);
        }
        let Some(job) = Job::restore(record) else {
            return;
        };
        if job.state() != JobState::Done
            && let Some(map_id) = job.map_id()
        {
            self.store.forget_claims(map_id);
        }
        let job = Arc::new(job);
        self.by_id
            .lock()
            .expect("jobs lock")
            .insert(job.id.clone(), job.clone());
        let forgotten = {
            let mut history = self.history.lock().expect("jobs lock");
            history.push(&job);
            history.trim()
        };
        for old in forgotten {
            self.by_id.lock().expect("jobs lock").remove(&old);
            if let Some(disk) = &self.disk {
                disk.remove_json(Kind::Job, old.as_str());
            }
        }
    }

    pub fn get(&self, id: &JobId) -> Option<Arc<Job>> {
        self.by_id.lock().expect("jobs lock").get(id).cloned()
    }

    /// Cancels every queued and running job (shutdown); returns their ids. With a data
    /// directory, the map builds among them are recorded as queued, and the next start resumes
    /// them ([`Jobs::restore`]).
    pub fn cancel_all(&self) -> Vec<JobId> {
        self.live()
            .into_iter()
            .map(|job| {
                // A job its owners cancelled already stays cancelled.
                if !job.progress.is_cancelled() {
                    job.interrupted.store(true, Ordering::SeqCst);
                }
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
            .filter(|j| j.visible_to(caller))
            .map(|j| (j.seq, j.view()))
            .collect();
        all.sort_by_key(|(seq, _)| std::cmp::Reverse(*seq));
        all
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

    /// Jobs waiting for a worker and jobs running now, for the gauges `/metrics` sets as it
    /// renders.
    pub(crate) fn depth(&self) -> (usize, usize) {
        (
            self.queued.load(Ordering::SeqCst),
            self.worker_count
                .saturating_sub(self.workers.available_permits()),
        )
    }

    /// Refuses a new job while `queue` jobs already wait beyond the free workers.
    fn check_room(&self) -> Result<(), Error> {
        if self.queued.load(Ordering::SeqCst) >= self.queue_limit + self.workers.available_permits()
        {
            return Err(Error::QueueFull {
                limit: self.queue_limit,
            });
        }
        Ok(())
    }

    /// Creates a queued job and records it.
    fn admit(&self, scenario_id: ScenarioId, owner: Option<Owner>, work: Work) -> Arc<Job> {
        self.admit_as(JobId::random(), scenario_id, Owners::of(owner), work)
    }

    /// [`Jobs::admit`] under a given id (a cluster job keeps the id its record has).
    fn admit_as(&self, id: JobId, scenario_id: ScenarioId, owners: Owners, work: Work) -> Arc<Job> {
        let (state, _) = watch::channel(JobState::Queued);
        let job = Arc::new(Job {
            id,
            seq: self.next_seq.fetch_add(1, Ordering::Relaxed),
            owners: Mutex::new(owners),
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
            interrupted: Default::default(),
        });
        metrics::gauge!("irs_jobs", "state" => JobState::Queued.as_str()).increment(1.0);
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
            tracing::info!("cancelled while queued");
            self.retire(&job, JobState::Cancelled).await;
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
            crate::priority::lower_this_thread();
            work()
        })
        .await;
        drop(permit);
        let seconds = started.elapsed().as_secs_f64();
        let ended = match result {
            Ok(Ok(output)) => {
                metrics::histogram!("irs_job_seconds", "kind" => job.kind().as_str())
                    .record(seconds);
                finish(job.clone(), output).await;
                tracing::info!(run_s = seconds, "job done");
                JobState::Done
            }
            Ok(Err(WorkError::Cancelled(Cancelled))) => {
                tracing::info!(
                    run_s = seconds,
                    cells_done = job.progress.cells_done(),
                    "job cancelled"
                );
                JobState::Cancelled
            }
            Ok(Err(WorkError::Invalid(e))) => {
                // Checked before the job was created; kept for completeness.
                *job.error.lock().expect("job lock") = Some(e.to_string());
                tracing::error!(error = %e, "job failed");
                JobState::Failed
            }
            Err(panic) => {
                *job.error.lock().expect("job lock") = Some(format!("the job panicked: {panic}"));
                tracing::error!(error = %panic, "job panicked");
                JobState::Failed
            }
        };
        self.retire(&job, ended).await;
    }

    /// Ends a job in the terminal state `ended`: its record is on disk (with `--data-dir`)
    /// before anyone can see it ended, so a client told "done" never loses the job to a crash;
    /// then it leaves the in-flight table, and the oldest finished jobs beyond the history's
    /// count or bytes are forgotten.
    async fn retire(&self, job: &Arc<Job>, ended: JobState) {
        let interrupted = ended == JobState::Cancelled && job.interrupted();
        // A cluster's shared build cut short here goes on elsewhere under the same id: no
        // record of it ending here, which would contradict the cluster's after a restart.
        let shared = matches!(
            job.work,
            job::Work::Map {
                resumable: false,
                ..
            }
        );
        let resumes = interrupted && job.resumes() && self.disk.is_some();
        if let Some(disk) = self.disk.clone().filter(|_| !(interrupted && shared)) {
            let record = if resumes {
                tracing::info!(job_id = %job.id, "interrupted by the shutdown: recorded to resume at the next start");
                job.record_interrupted()
            } else {
                job.record_as(ended)
            };
            let id = job.id.clone();
            // The rows a rate-map build solved go with its record (to resume from) or, once
            // it ends, go.
            let checkpoint = job
                .map_id()
                .cloned()
                .zip(job.checkpoint().cloned())
                .filter(|_| !shared);
            // Small files (a checkpoint: at most a map's rows), but flushed to disk: off the
            // async threads.
            let _ = crate::tasks::spawn_blocking(move || {
                if let Some((map_id, checkpoint)) = checkpoint {
                    let rows = if resumes {
                        checkpoint.all_rows()
                    } else {
                        Vec::new()
                    };
                    if rows.is_empty() {
                        disk.remove_checkpoint(map_id.as_str());
                    } else {
                        let bytes = irs_answers::encoding::encode_rows(&rows);
                        disk.save_checkpoint(map_id.as_str(), &bytes);
                    }
                }
                disk.save_json(Kind::Job, id.as_str(), &record)
            })
            .await;
        }
        job.set_state(ended);
        if let Some(map_id) = job.map_id() {
            self.in_flight.lock().await.remove(map_id);
            if job.state() != JobState::Done && !resumes {
                // No map came of it: the claims made on it while it ran claim nothing (unless
                // the next start resumes it, for the same owners).
                self.store.forget_claims(map_id);
            }
        }
        if resumes {
            // Not finished: out of the history, whose trimming would delete its record.
            return;
        }
        let forgotten = {
            let mut history = self.history.lock().expect("jobs lock");
            history.push(job);
            history.trim()
        };
        for old in forgotten {
            self.by_id.lock().expect("jobs lock").remove(&old);
            if let Some(disk) = &self.disk {
                disk.remove_json(Kind::Job, old.as_str());
            }
        }
    }

    /// Withdraws `caller`'s interest in a queued or running job, which stops when no owner
    /// wants it any more (at once with authentication off); a job the caller does not own is
    /// not found (404).
    pub fn cancel(&self, id: &JobId, caller: &Caller) -> Result<(Arc<Job>, Withdrawn), Error> {
        let job = self
            .get(id)
            .filter(|job| job.visible_to(caller))
            .ok_or_else(|| Error::not_found("job", id))?;
        let state = job.state();
        if state.is_terminal() {
            return Err(Error::JobFinished {
                job_id: id.clone(),
                state,
            });
        }
        let withdrawn = job
            .withdraw(caller)
            .ok_or_else(|| Error::not_found("job", id))?;
        if withdrawn == Withdrawn::Stopping {
            job.progress.cancel();
            job.cancel.notify_one();
        }
        Ok((job, withdrawn))
    }
}

/// The finished jobs kept for inspection, oldest first, with the bytes their answers weigh
/// (a placement's ranking is megabytes; a map job's record, nothing worth counting).
struct History {
    order: VecDeque<(JobId, usize)>,
    bytes: usize,
    /// `--job-history`.
    limit: usize,
    /// `--job-history-mb`, in bytes.
    budget: u64,
}

impl History {
    fn push(&mut self, job: &Job) {
        let weight = job.answer_bytes();
        self.push_weighed(job.id.clone(), weight);
    }

    fn push_weighed(&mut self, id: JobId, weight: usize) {
        self.order.push_back((id, weight));
        self.bytes += weight;
    }

    /// Forgets the oldest jobs until the rest fit the count and the bytes (the newest stays,
    /// so a placement's client can read its answer once it is done); returns their ids.
    fn trim(&mut self) -> Vec<JobId> {
        let mut forgotten = Vec::new();
        while self.order.len() > 1
            && (self.order.len() > self.limit || self.bytes as u64 > self.budget)
        {
            let Some((old, weight)) = self.order.pop_front() else {
                break;
            };
            self.bytes -= weight;
            forgotten.push(old);
        }
        if self.limit == 0 {
            // `--job-history 0`: nothing is kept, not even the newest.
            forgotten.extend(self.order.drain(..).map(|(id, _)| id));
            self.bytes = 0;
        }
        metrics::gauge!("irs_job_history_bytes").set(self.bytes as f64);
        forgotten
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn history(limit: usize, budget: u64) -> History {
        History {
            order: VecDeque::new(),
            bytes: 0,
            limit,
            budget,
        }
    }

    fn ids(forgotten: Vec<JobId>) -> Vec<String> {
        forgotten.iter().map(|id| id.as_str().to_string()).collect()
    }

    #[test]
    fn the_history_keeps_its_count_and_bytes_and_always_the_newest() {
        let mut h = history(3, 10);
        for (id, weight) in [("a", 4), ("b", 4)] {
            h.push_weighed(JobId::given(id), weight);
            assert!(h.trim().is_empty());
        }
        h.push_weighed(JobId::given("c"), 4);
        assert_eq!(ids(h.trim()), ["a"], "12 bytes > 10: the oldest goes");
        assert_eq!(h.bytes, 8);
        h.push_weighed(JobId::given("d"), 0);
        h.push_weighed(JobId::given("e"), 0);
        assert_eq!(ids(h.trim()), ["b"], "four jobs > 3");
        h.push_weighed(JobId::given("huge"), 50);
        assert_eq!(
            ids(h.trim()),
            ["c", "d", "e"],
            "heavier than the budget: kept alone"
        );
        assert_eq!(h.bytes, 50);
        let mut none = history(0, 10);
        none.push_weighed(JobId::given("x"), 1);
        assert_eq!(ids(none.trim()), ["x"], "--job-history 0 keeps nothing");
    }
}
