//! Maps, wherever they are: this replica's cache (memory, then its data directory), a build
//! in flight here, or (in a cluster) the shared store and the builds queued there. Handlers
//! ask [`App::map`], [`App::map_with_scenario`] or [`App::request_map`] and never choose
//! between the cache, the disk and Redis themselves.
//!
//! With tokens on, every map is reached through the caller's claim (kept by the
//! [`crate::store::Store`]): a tenant that never asked for a map is told it does not
//! exist (404, as for an unknown id, never 403), a listing shows only the caller's maps, and a
//! `DELETE` withdraws the caller's claim, deleting the map only with the last one. Asking for
//! a map another tenant already has adds a claim and answers as a new request would; only the
//! time it takes (a 200 at once where a fresh rate map would be a 202) can tell.

use super::identity::Caller;
use super::scenarios::{Named, ScenarioRef};
use super::{App, Error};
use crate::app::jobs::{JobRecord, JobState, JobView, MapRequestOutcome};
use crate::ids::{MapId, ScenarioId};
use crate::store::Entry;
use crate::store::redis::Cluster;
use irs_model::phases::PhaseMode;
use irs_model::radiomap::{MapKey, MapKind, RadioMap, cost};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;
use irs_model::solver::SolverKind;
use std::sync::Arc;

/// What defines a map: a scenario (registered id or inline document) and the map parameters.
pub(crate) struct MapSpec {
    pub scenario: ScenarioRef,
    pub kind: MapKind,
    pub phases: Option<PhaseMode>,
    pub access: Option<Access>,
    pub solver: Option<SolverKind>,
}

/// A requested map: ready (with the scenario it was built from), or being built by a job too
/// long to wait for (its view, for a 202).
pub(crate) enum Obtained {
    Ready {
        map: Arc<RadioMap>,
        scenario: Arc<Scenario>,
    },
    Building(Box<JobView>),
}

/// How often a request waiting for another replica's build reads its record: a gain map of
/// the sizes built inline takes tens of milliseconds, so the wait adds at most this.
const SHARED_POLL: std::time::Duration = std::time::Duration::from_millis(20);

/// Refuses work whose estimated CPU time exceeds the budget (422 naming `field` and the limit
/// in seconds), before any of it is done.
pub(crate) fn check_budget(
    field: &str,
    what: &str,
    seconds: f64,
    budget: f64,
) -> Result<(), Error> {
    if seconds <= budget {
        return Ok(());
    }
    Err(Error::limit_exceeded(
        field,
        budget.ceil() as u64,
        format!(
            "this {what} would take about {seconds:.0} s of CPU, above the server's budget of \
             {budget:.0} s: use a coarser grid, fewer elements (coherent grouping) or fewer \
             candidates or draws"
        ),
    ))
}

impl App {
    /// Records that `caller` asked for a map (nothing with authentication off).
    pub(crate) async fn claim_map(&self, caller: &Caller, map_id: &MapId) -> Result<(), Error> {
        let Some(owner) = caller.owner() else {
            return Ok(());
        };
        Ok(self.store().claim_map(map_id, &owner.to_string()).await?)
    }

    /// May `caller` see and touch the map? Always with authentication off; with it on, only a
    /// caller that asked for it.
    pub(crate) async fn may_see_map(&self, caller: &Caller, map_id: &MapId) -> Result<bool, Error> {
        Ok(match caller {
            Caller::Open => true,
            Caller::Anonymous => false,
            Caller::Owner(me) => self.store().map_claimed(map_id, &me.to_string()).await?,
        })
    }

    /// A built map by id for `caller` (a map it has no claim on is not found, whether or not
    /// it exists); not ready (with its job) while a build of it runs here or anywhere in the
    /// cluster.
    pub(crate) async fn map(
        &self,
        caller: &Caller,
        map_id: &MapId,
    ) -> Result<Arc<RadioMap>, Error> {
        if !self.may_see_map(caller, map_id).await? {
            return Err(Error::not_found("map", map_id));
        }
        self.any_map(map_id).await
    }

    /// The cached maps `caller` may see, by id.
    pub(crate) async fn list_maps(
        &self,
        caller: &Caller,
    ) -> Result<Vec<(MapId, Arc<RadioMap>)>, Error> {
        let mut visible = Vec::new();
        for (id, map) in self.cache().entries() {
            if self.may_see_map(caller, &id).await? {
                visible.push((id, map));
            }
        }
        Ok(visible)
    }

    /// A built map by id, whoever asked for it.
    async fn any_map(&self, map_id: &MapId) -> Result<Arc<RadioMap>, Error> {
        if let Some(map) = self.shared_map(map_id).await? {
            return Ok(map);
        }
        if let Some(job) = self.jobs().building(map_id).await {
            return Err(Error::MapNotReady {
                map_id: map_id.clone(),
                job_id: job.id.clone(),
            });
        }
        if let Some(job_id) = self.store().building(map_id).await? {
            return Err(Error::MapNotReady {
                map_id: map_id.clone(),
                job_id,
            });
        }
        Err(Error::not_found("map", map_id))
    }

    /// A built map and the scenario it was built from.
    pub(crate) async fn map_with_scenario(
        &self,
        caller: &Caller,
        map_id: &MapId,
    ) -> Result<(Arc<RadioMap>, Arc<Scenario>), Error> {
        let map = self.map(caller, map_id).await?;
        let stored = self
            .scenario(&ScenarioId::of_key(&map.key))
            .await?
            .ok_or_else(|| Error::not_found("scenario", &map.key.scenario_id))?;
        Ok((map, stored.scenario.clone()))
    }

    /// The map `spec` defines (its fields named under `prefix`): validated and budgeted, then
    /// taken from wherever it is built, or built (here, or in a cluster by whichever replica has
    /// a free worker). A cheap build is waited for; a long one answers with its job.
    pub(crate) async fn request_map(
        &self,
        caller: &Caller,
        spec: MapSpec,
        prefix: &str,
    ) -> Result<Obtained, Error> {
        let (scenario, key) = self.resolve(caller, spec, prefix).await?;
        let cheap =
            key.kind == MapKind::Gain && scenario.grid().cells() <= self.limits().sync_cells;
        let found = match self.build_stream() {
            Some(cluster) => self.obtain_shared(cluster, caller, key, cheap).await?,
            None => self.obtain(caller, scenario.clone(), key, cheap).await?,
        };
        Ok(match found {
            Ok(map) => Obtained::Ready { map, scenario },
            Err(job) => Obtained::Building(Box::new(job)),
        })
    }

    /// Withdraws `caller`'s claim on a built map; with the last claim (or with authentication
    /// off) the map is dropped here and from the shared store (the next request for it builds
    /// it again). A map being built here is not ready: cancel its job instead.
    pub(crate) async fn delete_map(&self, caller: &Caller, map_id: &MapId) -> Result<(), Error> {
        if !self.may_see_map(caller, map_id).await? {
            return Err(Error::not_found("map", map_id));
        }
        if let Some(job) = self.jobs().building(map_id).await {
            return Err(Error::MapNotReady {
                map_id: map_id.clone(),
                job_id: job.id.clone(),
            });
        }
        if let Caller::Owner(me) = caller {
            // The last claim deletes the store's copy with it.
            match self.store().withdraw_map(map_id, &me.to_string()).await? {
                None => return Err(Error::not_found("map", map_id)),
                Some(0) => {
                    self.cache().remove(map_id).await;
                    tracing::info!(map_id = %map_id, "map deleted with its last claim");
                }
                Some(left) => {
                    tracing::info!(map_id = %map_id, left, "a claim on a map withdrawn");
                }
            }
            return Ok(());
        }
        let removed_here = self.cache().remove(map_id).await;
        if !(self.store().delete(Entry::Map(map_id)).await? || removed_here) {
            return Err(Error::not_found("map", map_id));
        }
        tracing::info!(map_id = %map_id, "map deleted");
        Ok(())
    }

    /// Resolves a map request to a scenario and a normalised key, and checks the build's
    /// estimated cost against the budget. An inline scenario is registered (for `caller`) only
    /// once the whole request has been validated, so a rejected request leaves no trace.
    async fn resolve(
        &self,
        caller: &Caller,
        spec: MapSpec,
        prefix: &str,
    ) -> Result<(Arc<Scenario>, MapKey), Error> {
        let Named {
            id,
            scenario,
            inline,
        } = self.named_scenario(caller, spec.scenario, prefix).await?;
        let key = MapKey::new(
            id.as_str(),
            &scenario,
            spec.kind,
            spec.phases,
            spec.access,
            spec.solver,
        )
        .map_err(|e| e.within(prefix))?;
        let cells = scenario.grid().cells();
        let limit = self.limits().max_rate_cells;
        if key.kind == MapKind::Rate && cells > limit {
            return Err(Error::limit_exceeded(
                format!("{prefix}kind"),
                limit as u64,
                format!("rate maps are limited to {limit} cells; this grid has {cells}"),
            ));
        }
        check_budget(
            &format!("{prefix}kind"),
            "map build",
            cost::build_seconds(&scenario, &key),
            self.limits().max_build_cpu_s,
        )?;
        // A map the cache could never hold would be built, handed out once and dropped: refuse
        // it.
        let (bytes, budget) = (cost::map_bytes(&scenario, &key), self.limits().cache_bytes);
        if bytes > budget as f64 {
            return Err(Error::limit_exceeded(
                format!("{prefix}kind"),
                budget,
                format!(
                    "this map would take about {:.0} MiB, more than the map cache's whole budget of \
                     {} MiB (--cache-mb): use a coarser grid or fewer elements",
                    bytes / 1048576.0,
                    budget / 1048576
                ),
            ));
        }
        if let Some(shared) = self.limits().shared_maps_bytes
            && bytes > shared as f64
        {
            return Err(Error::limit_exceeded(
                format!("{prefix}kind"),
                shared,
                format!(
                    "this map would take about {:.0} MiB, more than the shared store's whole budget \
                     for maps of {} MiB (--redis-maps-mb): use a coarser grid or fewer elements",
                    bytes / 1048576.0,
                    shared / 1048576
                ),
            ));
        }
        if inline {
            let (stored, _) = self.register_api_scenario(scenario, caller).await?;
            return Ok((stored.scenario.clone(), key));
        }
        Ok((scenario, key))
    }

    /// The map from this replica's cache or build, waiting for cheap builds; `Err` is the job
    /// building a long one.
    async fn obtain(
        &self,
        caller: &Caller,
        scenario: Arc<Scenario>,
        key: MapKey,
        cheap: bool,
    ) -> Result<Result<Arc<RadioMap>, JobView>, Error> {
        let map_id = MapId::of(&key);
        let outcome = self
            .jobs()
            .request(self.cache(), scenario, key, caller.owner())
            .await?;
        self.claim_map(caller, &map_id).await?;
        match outcome {
            MapRequestOutcome::Ready(map) => Ok(Ok(map)),
            MapRequestOutcome::Building(job) if cheap => {
                // The job delivers its map itself, whatever the cache has done with it since.
                match job.wait_for_map().await {
                    Some(map) => Ok(Ok(map)),
                    None => Err(Error::BuildFailed(job.view().error.unwrap_or_else(|| {
                        format!("job {} ended {} without a map", job.id, job.state())
                    }))),
                }
            }
            MapRequestOutcome::Building(job) => Ok(Err(job.view())),
        }
    }

    /// [`App::obtain`] in a cluster: the map from any replica's build. The build is queued in
    /// the shared stream (once for the whole cluster) and runs on whichever replica has a free
    /// worker; a cheap one is waited for by polling its record.
    async fn obtain_shared(
        &self,
        cluster: &Cluster,
        caller: &Caller,
        key: MapKey,
        cheap: bool,
    ) -> Result<Result<Arc<RadioMap>, JobView>, Error> {
        let map_id = MapId::of(&key);
        if let Some(map) = self.shared_map(&map_id).await? {
            self.claim_map(caller, &map_id).await?;
            return Ok(Ok(map));
        }
        // The replica that builds it reads the scenario from the shared store.
        let stored = self
            .scenario(&ScenarioId::of_key(&key))
            .await?
            .ok_or_else(|| Error::not_found("scenario", &key.scenario_id))?;
        self.share_scenario(&stored, false).await?;
        let queued = JobRecord::queued(&key, caller.owner().as_ref());
        // A lock can name a job that has no record and no build (its holder died between the
        // two writes, or the lock was written by hand): once the lock has gone (it always
        // expires, see `Cluster::building`) the build is queued again, a few times at most.
        for _ in 0..3 {
            let (job_id, _) = cluster
                .enqueue(
                    &map_id,
                    &key,
                    (&queued.view.job_id, &queued),
                    self.limits().cluster_queue,
                )
                .await?;
            // The build is shared by everyone who asked: each one's cancel withdraws only its
            // own interest (`irs:job-owners`), and the map is theirs once built.
            if let Some(owner) = caller.owner() {
                cluster.join_job(&job_id, &owner.to_string()).await?;
            }
            self.claim_map(caller, &map_id).await?;
            let record = |r: Option<JobRecord>| {
                r.unwrap_or_else(|| {
                    let mut r = JobRecord::queued(&key, None);
                    r.view.job_id = job_id.clone();
                    r
                })
            };
            if !cheap {
                return Ok(Err(
                    record(self.store().record(Entry::Job(&job_id)).await?).view
                ));
            }
            loop {
                let found = self.store().record(Entry::Job(&job_id)).await?;
                if found.is_none()
                    && self.store().building(&map_id).await?.as_ref() != Some(&job_id)
                {
                    if let Some(map) = self.shared_map(&map_id).await? {
                        return Ok(Ok(map));
                    }
                    tracing::warn!(job_id = %job_id, map_id = %map_id, "build lock named a job without a record; queued again");
                    break;
                }
                let current = record(found);
                match current.view.state {
                    JobState::Done => {
                        return match self.shared_map(&map_id).await? {
                            Some(map) => Ok(Ok(map)),
                            None => Err(Error::BuildFailed(format!(
                                "job {job_id} is done but its map is in no store"
                            ))),
                        };
                    }
                    s if s.is_terminal() => {
                        return Err(Error::BuildFailed(current.view.error.unwrap_or_else(
                            || format!("job {job_id} ended {s} without a map"),
                        )));
                    }
                    _ => tokio::time::sleep(SHARED_POLL).await,
                }
            }
        }
        Err(Error::unavailable(
            "the map's build was lost three times in a row; retry",
        ))
    }

    /// A built map by id: in this replica's cache (or data directory), else in the store
    /// (another replica's), decoded against its scenario and cached here.
    async fn shared_map(
        &self,
        map_id: &MapId,
    ) -> Result<Option<Arc<irs_model::radiomap::RadioMap>>, Error> {
        if let Some(map) = self.cache().get(map_id).await {
            return Ok(Some(map));
        }
        let store = self.store();
        let Some(encoded) = store.get(Entry::Map(map_id)).await? else {
            return Ok(None);
        };
        // A map that frames correctly but does not decode to itself was not written by this
        // build: deleted, so it is built again rather than a 500 on every request.
        let key = match irs_answers::encoding::peek_key(&encoded) {
            Ok(key) => key,
            Err(e) => {
                store.discard(Entry::Map(map_id), &e.to_string()).await;
                return Ok(None);
            }
        };
        let Some(stored) = self.scenario(&ScenarioId::of_key(&key)).await? else {
            return Ok(None);
        };
        let scenario = stored.scenario.clone();
        let decoded = crate::tasks::spawn_blocking(move || {
            irs_answers::encoding::decode(&encoded, &scenario)
        })
        .await
        .map_err(|e| Error::internal(e.to_string()))?;
        let map = match decoded {
            Ok(map) if map.id == map_id.as_str() => map,
            Ok(_) => {
                store
                    .discard(Entry::Map(map_id), "it holds another map")
                    .await;
                return Ok(None);
            }
            Err(e) => {
                store.discard(Entry::Map(map_id), &e.to_string()).await;
                return Ok(None);
            }
        };
        let map = Arc::new(map);
        self.cache().insert(map_id.clone(), map.clone()).await;
        Ok(Some(map))
    }
}
