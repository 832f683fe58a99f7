//! The application: what the service does, independent of HTTP. [`App`] is the facade the
//! handlers call: it owns the scenario registry, the map and answer caches, the jobs, the query
//! pool, identity and, in a cluster, the coordination through the shared store, so a handler
//! never chooses between memory, disk and Redis. Its errors ([`Error`]) carry no status code
//! (`http::problem` maps them), and identity ([`identity`]: tokens, owners, callers) is decided
//! here, not in the transport.

pub(crate) mod answers;
pub(crate) mod builder;
pub(crate) mod cache;
pub(crate) mod deletions;
pub(crate) mod error;
pub(crate) mod identity;
pub(crate) mod jobs;
pub(crate) mod maps;
pub(crate) mod queries;
pub(crate) mod registry;
pub(crate) mod scenarios;
mod work;

pub(crate) use work::Component;

pub(crate) use error::Error;

use crate::config::ServeArgs;
use crate::ids::ScenarioId;
use crate::store::{self, Store, redis::Cluster};
use answers::AnswerCache;
use cache::{MapCache, MapDisk};
use identity::{Caller, Tokens};
use irs_answers::scenario::BUILTIN;
use irs_answers::scenario::ScenarioDocument as _;
use irs_model::scenario::Scenario;
use jobs::Jobs;
use metrics_exporter_prometheus::PrometheusHandle;
use queries::QueryPool;
use registry::{ScenarioRecord, ScenarioRegistry, ScenarioSource, StoredScenario};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Duration;

/// Request limits, from the configuration.
#[derive(Debug, Clone)]
pub(crate) struct Limits {
    pub max_body_bytes: usize,
    /// The body limit of `POST /v1/scenarios`, where floor plans travel.
    pub max_scenario_body_bytes: usize,
    pub sync_cells: usize,
    pub max_rate_cells: usize,
    pub max_sweep: usize,
    pub max_draws: usize,
    pub max_build_cpu_s: f64,
    pub max_check_cpu_s: f64,
    /// The map cache's budget: a map estimated bigger is refused before its build.
    pub cache_bytes: u64,
    /// In a cluster: the budget of the maps in Redis (`--redis-maps-mb`), which a map estimated
    /// bigger would empty on its own.
    pub shared_maps_bytes: Option<u64>,
    pub body_timeout: Duration,
    pub request_timeout: Duration,
    /// In a cluster: builds queued or running in the whole stream before a request gets 503
    /// (`--queue` + `--workers` of this replica: the same bound one replica alone has).
    pub cluster_queue: usize,
}

/// Shared state of the handlers.
#[derive(Clone)]
pub struct App {
    inner: Arc<Inner>,
}

struct Inner {
    limits: Limits,
    registry: Arc<ScenarioRegistry>,
    cache: MapCache,
    /// What the deployment's nodes share: the claims on maps and, in a cluster, every
    /// replica's scenarios, maps, build locks and job records.
    store: Arc<dyn Store>,
    /// `--redis-url`, if set: the cluster's build stream (the store, seen as the queue every
    /// replica's builds go through).
    stream: Option<Arc<Cluster>>,
    answers: AnswerCache,
    jobs: Arc<Jobs>,
    queries: QueryPool,
    tokens: Tokens,
    /// `--data-dir`, if set (the registry, the cache and the jobs write to it).
    disk: Option<Arc<store::DataDir>>,
    ready: AtomicBool,
    /// Cluster builds whose task is still running here (`builder`), which a shutdown waits
    /// for as it waits for jobs: an interrupted one stores its last checkpoint after its job
    /// has ended.
    shared_builds: Arc<AtomicUsize>,
    metrics: PrometheusHandle,
    /// The process's own series (CPU, memory, file descriptors, threads), read at each scrape.
    process: metrics_process::Collector,
}

/// A cluster build's task, counted in [`App::shared_builds`] while it lives.
pub(crate) struct SharedBuildRunning(Arc<AtomicUsize>);

impl Drop for SharedBuildRunning {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::Relaxed);
    }
}

impl App {
    /// The state for `args`; an error names the setting that is wrong.
    pub fn new(args: &ServeArgs, metrics: PrometheusHandle) -> Result<Self, String> {
        let positive = |flag: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(format!(
                    "{flag} must be a positive number of seconds, got {v}"
                ))
            }
        };
        let mb = |v: u64| usize::try_from(v.saturating_mul(1024 * 1024)).unwrap_or(usize::MAX);
        let disk = match &args.data_dir {
            Some(dir) => Some(Arc::new(store::DataDir::open(
                dir,
                args.data_maps_mb.saturating_mul(1024 * 1024),
                args.cache_mb.saturating_mul(1024 * 1024),
            )?)),
            None => None,
        };
        let registry = Arc::new(ScenarioRegistry::new(
            args.max_scenarios,
            mb(args.registry_mb),
            disk.clone(),
        ));
        let stream = match &args.redis_url {
            Some(url) => Some(Arc::new(Cluster::new(
                url,
                args.redis_maps_mb.saturating_mul(1024 * 1024),
            )?)),
            None => None,
        };
        let store: Arc<dyn Store> = match (&stream, &disk) {
            (Some(cluster), _) => cluster.clone(),
            (None, Some(dir)) => dir.clone(),
            (None, None) => Arc::new(store::Memory::default()),
        };
        let cache = MapCache::new(
            args.cache_mb.saturating_mul(1024 * 1024),
            disk.clone().map(|dir| MapDisk {
                dir,
                scenarios: registry.clone(),
            }),
            store.clone(),
        );
        Ok(App {
            inner: Arc::new(Inner {
                limits: Limits {
                    max_body_bytes: args.max_body_kb.saturating_mul(1024),
                    max_scenario_body_bytes: args
                        .max_scenario_body_kb
                        .max(args.max_body_kb)
                        .saturating_mul(1024),
                    sync_cells: args.sync_cells,
                    max_rate_cells: args.max_rate_cells,
                    max_sweep: args.max_sweep,
                    max_draws: args.max_draws.min(irs_model::montecarlo::MAX_DRAWS),
                    max_build_cpu_s: positive("--max-build-cpu-s", args.max_build_cpu_s)?,
                    max_check_cpu_s: positive("--max-check-cpu-s", args.max_check_cpu_s)?,
                    cache_bytes: args.cache_mb.saturating_mul(1024 * 1024),
                    shared_maps_bytes: args
                        .redis_url
                        .is_some()
                        .then(|| args.redis_maps_mb.saturating_mul(1024 * 1024)),
                    body_timeout: Duration::from_secs(args.body_timeout_s.max(1)),
                    request_timeout: Duration::from_secs(args.request_timeout_s.max(1)),
                    cluster_queue: args.queue + args.workers(),
                },
                registry,
                cache,
                store: store.clone(),
                stream,
                answers: AnswerCache::new(args.answer_cache_mb.saturating_mul(1024 * 1024)),
                jobs: Arc::new(Jobs::new(
                    args.workers(),
                    args.queue,
                    args.job_history,
                    args.job_history_mb.saturating_mul(1 << 20),
                    disk.clone(),
                    store,
                )),
                queries: QueryPool::new(args.query_workers(), args.query_queue)?,
                tokens: Tokens::load(&args.api_tokens, args.api_tokens_file.as_deref())?,
                disk,
                ready: AtomicBool::new(false),
                shared_builds: Arc::default(),
                metrics,
                process: metrics_process::Collector::default(),
            }),
        })
    }
    pub(crate) fn limits(&self) -> &Limits {
        &self.inner.limits
    }
    pub(crate) fn registry(&self) -> &ScenarioRegistry {
        &self.inner.registry
    }
    pub(crate) fn cache(&self) -> &MapCache {
        &self.inner.cache
    }
    /// The state the deployment's nodes share (see [`Store`]).
    pub(crate) fn store(&self) -> &dyn Store {
        &*self.inner.store
    }
    pub(crate) fn answers(&self) -> &AnswerCache {
        &self.inner.answers
    }
    pub(crate) fn jobs(&self) -> &Arc<Jobs> {
        &self.inner.jobs
    }
    pub(crate) fn queries(&self) -> &QueryPool {
        &self.inner.queries
    }
    pub(crate) fn tokens(&self) -> &Tokens {
        &self.inner.tokens
    }
    /// Registers a scenario for `caller` (whether it is new *to the caller*: with tokens on,
    /// a document another tenant registered is new to this one). When the registry is full,
    /// API scenarios are evicted by fair share (see [`ScenarioRegistry`]) and the maps built
    /// from them go with them.
    pub(crate) fn register_scenario(
        &self,
        scenario: Scenario,
        source: ScenarioSource,
        caller: &Caller,
    ) -> Result<(Arc<StoredScenario>, bool), Error> {
        let registered = self
            .registry()
            .register(scenario, source, caller.owner(), || {
                // Only a live job pins a scenario: a cached map is evicted with it.
                self.jobs()
                    .live()
                    .into_iter()
                    .map(|job| job.scenario_id.clone())
                    .collect()
            })?;
        if !registered.evicted.is_empty() {
            let cache = self.cache().clone();
            // The maps are dropped off the caller's path (memory and disk); until then a map
            // of an evicted scenario is still served from memory, which is harmless.
            crate::tasks::spawn(async move {
                for id in registered.evicted {
                    cache.remove_scenario_maps(&id).await;
                }
            });
        }
        Ok((registered.stored, registered.created))
    }

    /// Registers a scenario a request sent (or another replica shared) for `caller`: its
    /// canonical form is hashed and, with a data dir, written, on the query pool when it
    /// carries a floor plan of more than `queries::INLINE_BYTES`.
    pub(crate) async fn register_api_scenario(
        &self,
        scenario: Arc<Scenario>,
        caller: &Caller,
    ) -> Result<(Arc<StoredScenario>, bool), Error> {
        let (app, caller) = (self.clone(), caller.clone());
        self.queries()
            .run_sized("scenario", scenario.raster_bytes(), move || {
                app.register_scenario(Arc::unwrap_or_clone(scenario), ScenarioSource::Api, &caller)
            })
            .await?
    }

    /// In a cluster, the stream every replica's map builds queue in: the one thing a lone
    /// node does differently (its builds queue in its own pool).
    pub(crate) fn build_stream(&self) -> Option<&Arc<Cluster>> {
        self.inner.stream.as_ref()
    }

    /// `--data-dir`, if set (for its write probe and `/readyz`).
    pub(crate) fn data_dir(&self) -> Option<&Arc<store::DataDir>> {
        self.inner.disk.as_ref()
    }

    /// Whether the server has finished starting (and not begun stopping).
    pub fn is_ready(&self) -> bool {
        self.inner.ready.load(Ordering::Relaxed)
    }
    pub(crate) fn set_ready(&self, ready: bool) {
        self.inner.ready.store(ready, Ordering::Relaxed)
    }
    /// Counts a cluster build's task as running here until the guard drops.
    pub(crate) fn shared_build_running(&self) -> SharedBuildRunning {
        self.inner.shared_builds.fetch_add(1, Ordering::Relaxed);
        SharedBuildRunning(self.inner.shared_builds.clone())
    }
    /// Cluster builds whose task is still running here.
    pub(crate) fn shared_builds(&self) -> usize {
        self.inner.shared_builds.load(Ordering::Relaxed)
    }
    /// `/metrics`: what was recorded, with the gauges read now (the process's series, the
    /// jobs waiting and running) set first.
    pub(crate) fn render_metrics(&self) -> String {
        self.inner.process.collect();
        let (waiting, running) = self.jobs().depth();
        metrics::gauge!("irs_jobs_waiting").set(waiting as f64);
        metrics::gauge!("irs_jobs_running").set(running as f64);
        self.inner.metrics.render()
    }
}

/// Who registers a recorded scenario again: each owner digest it was kept with, or nobody in
/// particular (authentication was off) when it has none.
fn registrants(owners: Vec<String>) -> Vec<Caller> {
    if owners.is_empty() {
        return vec![Caller::Open];
    }
    owners
        .into_iter()
        .map(|o| Caller::Owner(identity::Owner::from_digest(o)))
        .collect()
}

/// Loads the built-in scenarios, then every `*.json` in `dir` (a missing directory is fine; an
/// invalid or unreadable file is skipped with a warning naming the file and the reason). Only
/// a built-in scenario that does not register is an error.
pub fn preload(state: &App, dir: &std::path::Path) -> Result<(), String> {
    for (name, text) in BUILTIN {
        let scenario =
            Scenario::from_json(text).map_err(|e| format!("built-in scenario {name}: {e}"))?;
        state
            .register_scenario(scenario, ScenarioSource::Builtin, &Caller::Open)
            .map_err(|e| e.to_string())?;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        tracing::info!(dir = %dir.display(), "no scenarios directory; serving the built-in scenarios");
        return Ok(());
    };
    let mut files: Vec<_> = entries
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    files.sort();
    // One bad file is the operator's to fix, not a reason to serve none of the others: it is
    // logged (path and reason) and skipped, and the summary counts it.
    let (mut loaded, mut skipped) = (0, 0);
    for path in files {
        let registered = Scenario::from_file(&path)
            .map_err(|e| e.to_string())
            .and_then(|scenario| {
                state
                    .register_scenario(scenario, ScenarioSource::File, &Caller::Open)
                    .map_err(|e| e.to_string())
            });
        match registered {
            Ok((stored, created)) => {
                loaded += 1;
                tracing::info!(file = %path.display(), scenario_id = %stored.id, new = created, "scenario loaded");
            }
            Err(reason) => {
                skipped += 1;
                tracing::warn!(file = %path.display(), reason, "scenario file skipped");
            }
        }
    }
    tracing::info!(dir = %dir.display(), loaded, skipped, "scenarios directory read");
    Ok(())
}

/// With `--data-dir`: registers the API scenarios recorded there (with their owners), takes
/// back the finished job records and resumes, under their ids, the map builds the last
/// shutdown interrupted. A record that is damaged, or no longer a valid scenario for this
/// build, is skipped with a warning. The maps are read from disk on demand, and into memory by
/// [`warm_from_disk`].
pub async fn restore(state: &App) {
    let Some(disk) = &state.inner.disk else {
        return;
    };
    let mut scenarios = 0;
    for (id, record) in disk.load_json::<ScenarioRecord>(store::Kind::Scenario) {
        let parsed = Scenario::from_json(&record.document.to_string());
        let scenario = match parsed {
            Ok(scenario) if ScenarioId::of(&scenario).as_str() == id => scenario,
            Ok(_) => {
                tracing::warn!(scenario_id = %id, "recorded scenario has another id in this build; skipped");
                continue;
            }
            Err(e) => {
                tracing::warn!(scenario_id = %id, error = %e, "recorded scenario is not valid in this build; skipped");
                continue;
            }
        };
        for owner in registrants(record.owners) {
            if let Err(e) = state.register_scenario(scenario.clone(), ScenarioSource::Api, &owner) {
                tracing::warn!(scenario_id = %id, error = %e, "recorded scenario not registered");
            }
        }
        scenarios += 1;
    }
    let (jobs, interrupted) = state.jobs().restore();
    let mut resumed = 0;
    for mut record in interrupted {
        let scenario = record
            .view
            .key
            .as_ref()
            .and_then(|key| state.registry().get(&ScenarioId::of_key(key)));
        record.view.finished_at = Some(
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0.0, |d| d.as_secs_f64()),
        );
        match scenario {
            // A replica resumes builds through the cluster's stream only (a record left by a
            // run without Redis is not one of the cluster's).
            Some(_) if state.build_stream().is_some() => {
                record.view.state = jobs::JobState::Cancelled;
                record.view.error = Some(
                    "interrupted by a shutdown when this server ran without Redis; request the map again"
                        .into(),
                );
            }
            Some(stored) => {
                let job = state
                    .jobs()
                    .resume(state.cache(), stored.scenario.clone(), &record)
                    .await;
                if job.is_some() {
                    resumed += 1;
                    tracing::info!(job_id = %record.view.job_id, "resumed a map build the last shutdown interrupted");
                    continue;
                }
                // Built meanwhile (its map was written before the record): done.
                record.view.state = jobs::JobState::Done;
            }
            None => {
                record.view.state = jobs::JobState::Failed;
                record.view.error =
                    Some("interrupted by a shutdown; its scenario is no longer registered".into());
            }
        }
        state.jobs().settle(record);
    }
    tracing::info!(scenarios, jobs, resumed, "restored from the data directory");
}

/// Loads the data directory's maps into memory, newest first, up to the cache's budget.
pub async fn warm_from_disk(state: &App) {
    state.cache().warm(state.limits().cache_bytes).await;
}
