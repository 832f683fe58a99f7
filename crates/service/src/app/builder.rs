//! The cluster's build loop: whenever this replica has a free worker it takes the next build
//! from the shared stream (a dead replica's first), builds the map as a local job, publishes
//! it to the shared store and keeps the job's record there current (heartbeats) until it ends.
//!
//! A rate map's build also leaves a checkpoint in the store: every [`CHECKPOINT_PERIOD`] the
//! grid rows solved since the last one, and the rest when a graceful stop interrupts it. The
//! replica that takes the build over (after a kill or a stop) copies those rows instead of
//! solving them again, so a kill costs at most the rows of one period, plus the rows that were
//! half done. Gain maps build in a few seconds and start again from zero.

use super::App;
use crate::app::jobs::{JobRecord, JobState, SharedBuild};
use crate::ids::ScenarioId;
use crate::store::redis::{BuildEntry, Cluster, HEALTH_PERIOD, HEARTBEAT};
use crate::store::{Entry, Error as StoreError, Store as _};
use irs_model::radiomap::{Checkpoint, RateRow};
use redis::aio::ConnectionManager;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// How often a running build appends the rows it solved to its checkpoint in the store: what
/// a killed builder's successor solves again, at most (the appends cost one `RPUSH` of the
/// rows' bytes each).
pub(crate) const CHECKPOINT_PERIOD: Duration = Duration::from_secs(2);

/// Reads builds from the stream whenever this replica has a free worker, forever (a task
/// per replica, started with the server).
pub(crate) async fn run(state: App, cluster: Arc<Cluster>) {
    let mut conn: Option<ConnectionManager> = None;
    loop {
        // Not ready: starting, or stopping, when a build taken now would be cut short.
        if !state.is_ready() || state.jobs().free_workers() == 0 || cluster.unavailable().is_some()
        {
            tokio::time::sleep(HEARTBEAT).await;
            continue;
        }
        let mut active = match conn.take() {
            Some(c) => c,
            None => match cluster.connect().await {
                Ok(c) => c,
                Err(_) => {
                    tokio::time::sleep(HEALTH_PERIOD).await;
                    continue;
                }
            },
        };
        match cluster.next_build(&mut active).await {
            Ok(Some(build)) => {
                crate::tasks::spawn(build_entry(state.clone(), cluster.clone(), build));
            }
            Ok(None) => {}
            Err(e) => {
                tracing::debug!(error = %e, "reading the build stream");
                tokio::time::sleep(HEALTH_PERIOD).await;
            }
        }
        conn = Some(active);
    }
}

/// Builds one stream entry on this replica: the map goes to Redis, the record follows the
/// build (heartbeats) and ends in its final state; the entry is acknowledged at the end.
async fn build_entry(state: App, cluster: Arc<Cluster>, build: BuildEntry) {
    let _running = state.shared_build_running();
    let record = state
        .store()
        .record::<JobRecord>(Entry::Job(&build.job_id))
        .await
        .ok()
        .flatten();
    // The owners the record names when the build starts; owners who join later are in the
    // store's `irs:job-owners` set, which is what every replica asks.
    let owners = record.as_ref().map(|r| r.owners()).unwrap_or_default();
    let end = |mut record: JobRecord, state: JobState, error: Option<String>| {
        record.view.state = state;
        record.view.error = error;
        record.view.finished_at = Some(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
        );
        record
    };
    let record = record.unwrap_or_else(|| {
        let mut r = JobRecord::queued(&build.key, None);
        r.view.job_id = build.job_id.clone();
        r
    });
    // Built already (a build taken over just after its map was stored), or cancelled while
    // it waited: nothing to build.
    if matches!(cluster.get(Entry::Map(&build.map_id)).await, Ok(Some(_))) {
        if !record.view.state.is_terminal() {
            let _ = cluster
                .put_job(&build.job_id, &end(record, JobState::Done, None))
                .await;
        }
        cluster.finish(&build).await;
        return;
    }
    if cluster.cancel_requested(&build.job_id).await {
        let _ = cluster
            .put_job(&build.job_id, &end(record, JobState::Cancelled, None))
            .await;
        cluster.finish(&build).await;
        return;
    }
    let scenario = match state.scenario(&ScenarioId::of_key(&build.key)).await {
        Ok(Some(stored)) => stored.scenario.clone(),
        other => {
            let reason = match other {
                Err(e) => e.to_string(),
                _ => format!("scenario {} is registered nowhere", build.key.scenario_id),
            };
            let _ = cluster
                .put_job(&build.job_id, &end(record, JobState::Failed, Some(reason)))
                .await;
            cluster.finish(&build).await;
            return;
        }
    };
    let publisher = cluster.clone();
    let map_id = build.map_id.clone();
    let scenario_id = ScenarioId::of_key(&build.key);
    // A map whose share failed (Redis down as the build ended) is kept here and shared below
    // once Redis answers again: its stream entry stays pending meanwhile, and a replica that
    // claimed it would otherwise build the map a second time under the same job.
    let unshared: Arc<Mutex<Option<Vec<u8>>>> = Arc::default();
    let keep = unshared.clone();
    let publish = move |map: std::sync::Arc<irs_model::radiomap::RadioMap>| async move {
        let encoded = crate::tasks::spawn_blocking(move || irs_answers::encoding::encode(&map))
            .await
            .map_err(|e| e.to_string())?;
        let shared = publisher.put_map(&map_id, &scenario_id, &encoded).await;
        if shared.is_ok() {
            // Shared, the map needs no checkpoint: deleted here, before the job says `done`
            // (`finish` deletes it again, for builds that end otherwise), so no one who sees
            // the job done finds its rows still held.
            publisher.remove_checkpoint(&map_id).await;
        }
        shared.map_err(|e| match e {
            // Retrying cannot make room: the map stays this replica's only (the others build
            // it again when asked), and the operator is told.
            StoreError::NoRoom { .. } => {
                metrics::counter!("irs_maps_not_shared_total", "reason" => "store_full")
                    .increment(1);
                format!("{}; not shared", super::Error::from(e))
            }
            e => {
                *keep.lock().expect("unshared map") = Some(encoded);
                format!(
                    "{}; kept to share when Redis answers",
                    super::Error::from(e)
                )
            }
        })
    };
    let checkpoint = Arc::new(Checkpoint::recording(
        resumed_rows(&cluster, &build.map_id).await,
    ));
    let shared = SharedBuild {
        job_id: build.job_id.clone(),
        scenario,
        key: build.key.clone(),
        owners,
        checkpoint: checkpoint.clone(),
    };
    let job = state.jobs().build_shared(shared, state.cache(), publish);
    tracing::info!(job_id = %build.job_id, map_id = %build.map_id, replica = %cluster.replica, resumed_rows = checkpoint.resumed_rows(), "building for the cluster");
    let mut saver = CheckpointSaver::default();
    loop {
        tokio::select! {
            _ = job.finished() => break,
            _ = tokio::time::sleep(HEARTBEAT) => {
                // A job that has just ended is recorded once, below: a shared record saying
                // "cancelled" while the shutdown hands the build over would end it for every
                // waiter on the other replicas (seen in CI when the heartbeat won the race).
                // The record is taken first, so the state checked is the state written.
                let record = job.record();
                if record.view.state.is_terminal() {
                    continue;
                }
                cluster.heartbeat(&build).await;
                let _ = cluster.put_job(&build.job_id, &record).await;
                if cluster.cancel_requested(&build.job_id).await {
                    state.jobs().cancel_local(&job);
                }
                if saver.last.elapsed() >= CHECKPOINT_PERIOD {
                    saver.save(&cluster, &build, &checkpoint).await;
                }
            }
        }
    }
    if job.interrupted() && job.state() == JobState::Cancelled {
        // This replica stops: the entry stays pending (no final record, no XACK), so the next
        // replica with a free worker takes the build over once it has been idle for
        // CLAIM_IDLE, and the job's waiters see it go on under the same id, from the rows
        // checkpointed here.
        saver.save(&cluster, &build, &checkpoint).await;
        tracing::info!(job_id = %build.job_id, map_id = %build.map_id, rows_saved = saver.rows, "build interrupted by the shutdown; left to another replica");
        return;
    }
    let kept = unshared.lock().expect("unshared map").take();
    if let Some(encoded) = kept {
        share_when_redis_answers(&cluster, &build, &encoded).await;
    }
    // The final record, written until it lands (Redis may be down just now): the job's
    // waiters on other replicas read it.
    let final_record = job.record();
    for attempt in 0..20u32 {
        if cluster.put_job(&build.job_id, &final_record).await.is_ok() {
            break;
        }
        tokio::time::sleep(HEALTH_PERIOD * (attempt + 1).min(4)).await;
    }
    cluster.finish(&build).await;
}

/// The rows an earlier builder of `map_id` checkpointed, decoded; a checkpoint that does not
/// decode is discarded (the build starts from zero rather than failing).
async fn resumed_rows(cluster: &Cluster, map_id: &crate::ids::MapId) -> Vec<RateRow> {
    let batches = match cluster.checkpoint(map_id).await {
        Ok(batches) => batches,
        Err(e) => {
            tracing::warn!(map_id = %map_id, error = %super::Error::from(e), "checkpoint unreadable; building from the first row");
            return Vec::new();
        }
    };
    let mut rows = Vec::new();
    for batch in &batches {
        match irs_answers::encoding::decode_rows(batch) {
            Ok(batch) => rows.extend(batch),
            Err(e) => {
                cluster.discard_checkpoint(map_id, &e.to_string()).await;
                return Vec::new();
            }
        }
    }
    if !rows.is_empty() {
        metrics::counter!("irs_map_rows_resumed_total").increment(rows.len() as u64);
    }
    rows
}

/// Appends a build's newly solved rows to its checkpoint. Rows an append could not store
/// (Redis away or full) wait for the next one: a checkpoint only ever lacks recent rows.
struct CheckpointSaver {
    last: Instant,
    unsaved: Vec<RateRow>,
    /// Rows stored so far.
    rows: usize,
}

impl Default for CheckpointSaver {
    fn default() -> Self {
        CheckpointSaver {
            last: Instant::now(),
            unsaved: Vec::new(),
            rows: 0,
        }
    }
}

impl CheckpointSaver {
    async fn save(&mut self, cluster: &Cluster, build: &BuildEntry, checkpoint: &Checkpoint) {
        self.last = Instant::now();
        self.unsaved.extend(checkpoint.take_solved());
        if self.unsaved.is_empty() {
            return;
        }
        let batch = irs_answers::encoding::encode_rows(&self.unsaved);
        match cluster.append_checkpoint(&build.map_id, &batch).await {
            Ok(()) => {
                self.rows += self.unsaved.len();
                metrics::counter!("irs_map_rows_checkpointed_total")
                    .increment(self.unsaved.len() as u64);
                self.unsaved.clear();
            }
            Err(e) => {
                tracing::debug!(map_id = %build.map_id, error = %super::Error::from(e), rows = self.unsaved.len(), "checkpoint not stored; kept for the next one");
            }
        }
    }
}

/// Stores a built map whose first share failed, retrying until Redis takes it. The builder
/// keeps its stream entry claimed meanwhile (heartbeats), so no replica that sees Redis again
/// first takes the entry over and builds the map anew. Bounded in memory: only the builds that
/// ended while Redis was down wait here (no new build is read from the stream meanwhile).
async fn share_when_redis_answers(cluster: &Cluster, build: &BuildEntry, encoded: &[u8]) {
    let mut attempt = 0u32;
    loop {
        cluster.heartbeat(build).await;
        match cluster
            .put_map(&build.map_id, &ScenarioId::of_key(&build.key), encoded)
            .await
        {
            Ok(()) => {
                tracing::info!(map_id = %build.map_id, attempts = attempt + 1, "kept map shared");
                metrics::counter!("irs_maps_shared_late_total").increment(1);
                return;
            }
            Err(e @ StoreError::NoRoom { .. }) => {
                metrics::counter!("irs_maps_not_shared_total", "reason" => "store_full")
                    .increment(1);
                tracing::error!(map_id = %build.map_id, error = %super::Error::from(e), "kept map not shared");
                return;
            }
            Err(e) if attempt.is_multiple_of(20) => {
                tracing::warn!(map_id = %build.map_id, error = %super::Error::from(e), "sharing the built map again");
            }
            Err(_) => {}
        }
        attempt += 1;
        // Every health period: within CLAIM_IDLE of Redis's return (see `Cluster::next_build`).
        tokio::time::sleep(HEALTH_PERIOD).await;
    }
}
