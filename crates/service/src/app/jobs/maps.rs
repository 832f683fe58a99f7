//! Map jobs and their single flight: while a map id is being built, every request for it gets
//! the same job; the finished map enters the cache *before* the job leaves the in-flight
//! table, so a request that arrives in between finds the map, never a second build. The
//! requests that wait for a job take the map from the job itself ([`Job::wait_for_map`]), not
//! from the cache, so a cache that evicts it at once (full of other maps) cannot fail them; the
//! job lets go of the map as soon as the last of them has it. Cancellation sets the build's
//! flag, which [`irs_model::radiomap::build`] checks once per grid row.

use super::Jobs;
use super::job::{Job, MapDelivery, Work};
use crate::app::Error;
use crate::app::cache::MapCache;
use crate::app::identity::{Owner, Owners};
use crate::ids::{JobId, MapId, ScenarioId};
use irs_model::radiomap::{Checkpoint, MapKey, MapKind, RadioMap, RateRow, WorkError};
use irs_model::scenario::Scenario;
use std::sync::{Arc, Mutex};
use tracing::Instrument;

/// A build taken from the cluster's stream, as [`Jobs::build_shared`] runs it.
pub(crate) struct SharedBuild {
    /// The job's id, the same on every replica.
    pub job_id: JobId,
    pub scenario: Arc<Scenario>,
    pub key: MapKey,
    pub owners: Owners,
    /// The rows an earlier builder left, where this build records its own.
    pub checkpoint: Arc<Checkpoint>,
}

/// The outcome of asking for a map.
pub enum MapRequestOutcome {
    Ready(Arc<RadioMap>),
    Building(Arc<Job>),
}

impl Jobs {
    /// The job building `map_id`, if one is queued or running.
    pub async fn building(&self, map_id: &MapId) -> Option<Arc<Job>> {
        self.in_flight.lock().await.get(map_id).cloned()
    }

    /// The map if cached, else the job building it (started now unless one is in flight; a
    /// job in flight adds `owner` to its owners).
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
            // A shared build: it now serves this owner too, until each has let go.
            job.join(owner);
            return Ok(MapRequestOutcome::Building(job.clone()));
        }
        self.check_room()?;
        // Rows are recorded only where a shutdown can keep them for the next start.
        let checkpoint = if self.disk.is_some() && key.kind == MapKind::Rate {
            Checkpoint::recording(Vec::new())
        } else {
            Checkpoint::default()
        };
        let job = self.admit_map(
            JobId::random(),
            &key,
            Owners::of(owner),
            Some(Arc::new(checkpoint)),
        );
        self.start_map(&mut in_flight, job.clone(), cache, scenario, key);
        Ok(MapRequestOutcome::Building(job))
    }

    /// Builds again, under its own id and for its owners, a map build the last shutdown
    /// interrupted (its record, from the data directory); nothing if the map is cached by now
    /// or being built.
    pub async fn resume(
        self: &Arc<Self>,
        cache: &MapCache,
        scenario: Arc<Scenario>,
        record: &super::record::JobRecord,
    ) -> Option<Arc<Job>> {
        let key = record.view.key.clone()?;
        let map_id = MapId::of(&key);
        let mut in_flight = self.in_flight.lock().await;
        if in_flight.contains_key(&map_id) || cache.get(&map_id).await.is_some() {
            return None;
        }
        let rows = self.checkpointed_rows(&map_id);
        if !rows.is_empty() {
            tracing::info!(job_id = %record.view.job_id, rows = rows.len(), "resuming from the rows the interrupted build had solved");
            metrics::counter!("irs_map_rows_resumed_total").increment(rows.len() as u64);
        }
        let checkpoint = Arc::new(Checkpoint::recording(rows));
        let job = self.admit_map(
            record.view.job_id.clone(),
            &key,
            record.owners(),
            Some(checkpoint),
        );
        self.start_map(&mut in_flight, job.clone(), cache, scenario, key);
        Some(job)
    }

    /// Runs the build of a map job just admitted, in flight from now on.
    fn start_map(
        self: &Arc<Self>,
        in_flight: &mut std::collections::HashMap<MapId, Arc<Job>>,
        job: Arc<Job>,
        cache: &MapCache,
        scenario: Arc<Scenario>,
        key: MapKey,
    ) {
        let map_id = MapId::of(&key);
        in_flight.insert(map_id.clone(), job.clone());
        let span = tracing::info_span!("job", job_id = %job.id, map_id = %map_id, scenario_id = %key.scenario_id);
        let progress = job.progress.clone();
        let cache = cache.clone();
        let checkpoint = job.checkpoint().cloned().unwrap_or_default();
        let work = move || {
            irs_answers::map::build_resuming(&scenario, &key, &progress, &checkpoint)
                .map_err(WorkError::from)
        };
        let finish = move |job: Arc<Job>, map: RadioMap| async move {
            let map = Arc::new(map);
            job.deliver(&map);
            cache.insert(map_id, map).await;
        };
        crate::tasks::spawn(self.clone().run(job, work, finish).instrument(span));
    }

    /// Builds a map another replica (or this one) queued in the cluster's stream, as the local
    /// job `build.job_id` (so this replica shows its live progress), resuming from the rows
    /// its checkpoint holds and recording there the rows it solves. When it is done, `publish`
    /// gets the map before the job says `done`, then the map enters `cache`. Counted in
    /// `irs_map_builds_total`, which in a cluster counts builds, not requests.
    pub(crate) fn build_shared<P, Fut>(
        self: &Arc<Self>,
        build: SharedBuild,
        cache: &MapCache,
        publish: P,
    ) -> Arc<Job>
    where
        P: FnOnce(Arc<RadioMap>) -> Fut + Send + 'static,
        Fut: std::future::Future<Output = Result<(), String>> + Send,
    {
        let SharedBuild {
            job_id,
            scenario,
            key,
            owners,
            checkpoint,
        } = build;
        let map_id = MapId::of(&key);
        let job = self.admit_map(job_id, &key, owners, None);
        // The builder keeps this one in Redis; the job holds none of its own.
        let span = tracing::info_span!("job", job_id = %job.id, map_id = %map_id, scenario_id = %key.scenario_id, shared = true);
        let progress = job.progress.clone();
        let cache = cache.clone();
        let work = move || {
            irs_answers::map::build_resuming(&scenario, &key, &progress, &checkpoint)
                .map_err(WorkError::from)
        };
        let built_id = map_id.clone();
        let finish = move |job: Arc<Job>, map: RadioMap| async move {
            let map = Arc::new(map);
            job.deliver(&map);
            if let Err(e) = publish(map.clone()).await {
                tracing::warn!(error = %e, "built map not shared yet");
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

    /// A map build admitted as job `id`, counted in `irs_map_builds_total`: one of this
    /// node's own, which a restart resumes, with its checkpoint, or (`None`) a cluster's
    /// shared build ([`Work::Map`]).
    fn admit_map(
        &self,
        id: JobId,
        key: &MapKey,
        owners: Owners,
        own: Option<Arc<Checkpoint>>,
    ) -> Arc<Job> {
        metrics::counter!("irs_map_builds_total", "kind" => key.kind.to_string()).increment(1);
        self.admit_as(
            id,
            ScenarioId::of_key(key),
            owners,
            Work::Map {
                map_id: MapId::of(key),
                key: key.clone(),
                delivery: Mutex::new(MapDelivery::default()),
                resumable: own.is_some(),
                checkpoint: own.unwrap_or_default(),
            },
        )
    }

    /// The rows an interrupted build of `map_id` left in the data directory (none without
    /// one, or if they do not decode).
    fn checkpointed_rows(&self, map_id: &MapId) -> Vec<RateRow> {
        let Some(bytes) = self
            .disk
            .as_ref()
            .and_then(|d| d.load_checkpoint(map_id.as_str()))
        else {
            return Vec::new();
        };
        irs_answers::encoding::decode_rows(&bytes)
            .inspect_err(|e| tracing::warn!(map_id = %map_id, error = %e, "checkpoint ignored"))
            .unwrap_or_default()
    }
}
