//! The HTTP planning service: axum on tokio, maps cached in moka, builds on a bounded blocking
//! pool, `tracing` spans per request and per job, Prometheus metrics. The contract is
//! `openapi.yaml`.
//!
//! Layout: [`config`] (flags and environment), [`api`] (routes and handlers), `cache` (scenario
//! registry, map cache and the maps' widest-path indexes), `answers` (path answers kept for
//! repeated queries), `jobs` (map builds and placement searches), `json` (large answers written
//! into one buffer, rounded numbers from integers), `queries` (admission
//! of heavy queries), `auth` (bearer tokens and ownership), `server` (the accept loop and its
//! timeouts), `store` (the data directory of `--data-dir`), `cluster` (replicas sharing Redis,
//! `--redis-url`), `errors` (problem+json; [`Problem`]
//! is the body of every error answer), `viewer` (the built-in map viewer at `/`).

pub(crate) mod answers;
pub mod api;
pub(crate) mod auth;
pub(crate) mod cache;
pub(crate) mod cluster;
pub mod config;
pub(crate) mod errors;
pub(crate) mod jobs;
pub(crate) mod json;
pub(crate) mod priority;
pub mod probe;
pub(crate) mod queries;
pub(crate) mod server;
pub(crate) mod store;
pub(crate) mod viewer;

pub use errors::Problem;

use answers::AnswerCache;
use auth::{Caller, Tokens};
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::http::{HeaderValue, Method, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use cache::{MapCache, MapDisk, ScenarioRecord, ScenarioRegistry};
use config::{LogFormat, ServeArgs};
use errors::ApiError;
use irs_answers::scenario::BUILTIN;
use irs_answers::scenario::ScenarioDocument;
use irs_model::scenario::Scenario;
use jobs::Jobs;
use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle};
use queries::QueryPool;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use tower::ServiceBuilder;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::TraceLayer;

/// Request limits, from the configuration.
#[derive(Debug, Clone)]
pub(crate) struct Limits {
    pub max_body_bytes: usize,
    pub sync_cells: usize,
    pub max_rate_cells: usize,
    pub max_sweep: usize,
    pub max_draws: usize,
    pub max_build_cpu_s: f64,
    pub max_check_cpu_s: f64,
    /// The map cache's budget: a map estimated bigger is refused before its build.
    pub cache_bytes: u64,
    pub body_timeout: Duration,
    pub request_timeout: Duration,
    /// In a cluster: builds queued or running in the whole stream before a request gets 503
    /// (`--queue` + `--workers` of this replica: the same bound one replica alone has).
    pub cluster_queue: usize,
}

/// Longest `x-request-id` taken from a client (a UUID is 36 characters); a longer one, or one
/// with characters outside `[A-Za-z0-9._:-]`, is replaced by a fresh UUID so logs stay clean.
const MAX_REQUEST_ID_CHARS: usize = 64;

/// Shared state of the handlers.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    limits: Limits,
    registry: Arc<ScenarioRegistry>,
    cache: MapCache,
    answers: AnswerCache,
    jobs: Arc<Jobs>,
    queries: QueryPool,
    tokens: Tokens,
    cors_origins: Vec<HeaderValue>,
    /// `--data-dir`, if set (the registry, the cache and the jobs write to it).
    disk: Option<Arc<store::DataDir>>,
    /// `--redis-url`, if set: the store shared with the other replicas.
    cluster: Option<Arc<cluster::Cluster>>,
    ready: AtomicBool,
    metrics: PrometheusHandle,
}

impl AppState {
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
        let cors_origins = args
            .cors_origin
            .iter()
            .map(|o| {
                HeaderValue::from_str(o.trim())
                    .ok()
                    .filter(|_| o.starts_with("http://") || o.starts_with("https://"))
                    .ok_or_else(|| format!("--cors-origin {o:?}: not an http(s) origin"))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let mb = |v: u64| usize::try_from(v.saturating_mul(1024 * 1024)).unwrap_or(usize::MAX);
        let disk = match &args.data_dir {
            Some(dir) => Some(Arc::new(store::DataDir::open(
                dir,
                args.data_maps_mb.saturating_mul(1024 * 1024),
            )?)),
            None => None,
        };
        let registry = Arc::new(ScenarioRegistry::new(
            args.max_scenarios,
            mb(args.registry_mb),
            disk.clone(),
        ));
        let cache = MapCache::new(
            args.cache_mb.saturating_mul(1024 * 1024),
            disk.clone().map(|dir| MapDisk {
                dir,
                scenarios: registry.clone(),
            }),
        );
        Ok(AppState {
            inner: Arc::new(Inner {
                limits: Limits {
                    max_body_bytes: args.max_body_kb.saturating_mul(1024),
                    sync_cells: args.sync_cells,
                    max_rate_cells: args.max_rate_cells,
                    max_sweep: args.max_sweep,
                    max_draws: args.max_draws.min(irs_model::montecarlo::MAX_DRAWS),
                    max_build_cpu_s: positive("--max-build-cpu-s", args.max_build_cpu_s)?,
                    max_check_cpu_s: positive("--max-check-cpu-s", args.max_check_cpu_s)?,
                    cache_bytes: args.cache_mb.saturating_mul(1024 * 1024),
                    body_timeout: Duration::from_secs(args.body_timeout_s.max(1)),
                    request_timeout: Duration::from_secs(args.request_timeout_s.max(1)),
                    cluster_queue: args.queue + args.workers(),
                },
                registry,
                cache,
                answers: AnswerCache::new(args.answer_cache_mb.saturating_mul(1024 * 1024)),
                jobs: Arc::new(Jobs::new(
                    args.workers(),
                    args.queue,
                    args.job_history,
                    disk.clone(),
                )),
                queries: QueryPool::new(args.query_workers(), args.query_queue)?,
                tokens: Tokens::load(&args.api_tokens, args.api_tokens_file.as_deref())?,
                cors_origins,
                disk,
                cluster: match &args.redis_url {
                    Some(url) => Some(Arc::new(cluster::Cluster::new(url)?)),
                    None => None,
                },
                ready: AtomicBool::new(false),
                metrics,
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
    /// Registers a scenario for `caller`, evicting the least recently used unneeded ones if the
    /// registry is full (see [`ScenarioRegistry`]).
    pub(crate) fn register_scenario(
        &self,
        scenario: Scenario,
        source: &'static str,
        caller: &Caller,
    ) -> Result<(Arc<cache::StoredScenario>, bool), ApiError> {
        self.registry()
            .register(scenario, source, caller.owner(), || {
                let mut needed = self.cache().scenario_ids();
                needed.extend(
                    self.jobs()
                        .live()
                        .into_iter()
                        .map(|job| job.scenario_id.clone()),
                );
                needed
            })
    }

    pub(crate) fn cluster(&self) -> Option<&Arc<cluster::Cluster>> {
        self.inner.cluster.as_ref()
    }

    /// A scenario by id: registered here, or (in a cluster) registered on another replica,
    /// which registers it here too with its owners. `Ok(None)`: nowhere; 503 while the shared
    /// store is down and the scenario is not here.
    pub(crate) async fn shared_scenario(
        &self,
        id: &str,
    ) -> Result<Option<Arc<cache::StoredScenario>>, ApiError> {
        if let Some(stored) = self.registry().get(id) {
            return Ok(Some(stored));
        }
        let Some(cluster) = self.cluster() else {
            return Ok(None);
        };
        let Some(record) = cluster.scenario(id).await? else {
            return Ok(None);
        };
        let scenario = Scenario::from_json(&record.document.to_string())
            .map_err(|e| ApiError::internal(format!("shared scenario {id}: {e}")))?;
        if scenario.content_hash() != id {
            return Err(ApiError::internal(format!(
                "shared scenario {id} has another id in this build"
            )));
        }
        let mut stored = None;
        for owner in registrants(record.owners) {
            stored = Some(self.register_scenario(scenario.clone(), "api", &owner)?.0);
        }
        Ok(stored)
    }

    /// In a cluster: publishes an API scenario (document and owners) for the other replicas;
    /// `replace` false leaves a record already there as it is (see [`cluster::Cluster::put_scenario`]).
    pub(crate) async fn share_scenario(
        &self,
        stored: &cache::StoredScenario,
        replace: bool,
    ) -> Result<(), ApiError> {
        match self.cluster() {
            Some(cluster) if stored.source == "api" => {
                cluster
                    .put_scenario(&stored.id, &stored.record(), replace)
                    .await
            }
            _ => Ok(()),
        }
    }

    /// A built map by id: in this replica's cache (or data directory), else (in a cluster) in
    /// the shared store, decoded against its scenario and cached here.
    pub(crate) async fn shared_map(
        &self,
        map_id: &str,
    ) -> Result<Option<Arc<irs_model::radiomap::RadioMap>>, ApiError> {
        if let Some(map) = self.cache().get(map_id).await {
            return Ok(Some(map));
        }
        let Some(cluster) = self.cluster() else {
            return Ok(None);
        };
        let Some(encoded) = cluster.map(map_id).await? else {
            return Ok(None);
        };
        let key = irs_answers::encoding::peek_key(&encoded)
            .map_err(|e| ApiError::internal(format!("shared map {map_id}: {e}")))?;
        let Some(stored) = self.shared_scenario(&key.scenario_id).await? else {
            return Ok(None);
        };
        let scenario = stored.scenario.clone();
        let map =
            tokio::task::spawn_blocking(move || irs_answers::encoding::decode(&encoded, &scenario))
                .await
                .map_err(|e| ApiError::internal(e.to_string()))?
                .map_err(|e| ApiError::internal(format!("shared map {map_id}: {e}")))?;
        if map.id != map_id {
            return Err(ApiError::internal(format!(
                "shared map {map_id} holds another map"
            )));
        }
        let map = Arc::new(map);
        self.cache().insert(map_id.to_string(), map.clone()).await;
        Ok(Some(map))
    }

    pub fn is_ready(&self) -> bool {
        self.inner.ready.load(Ordering::Relaxed)
    }
    fn set_ready(&self, ready: bool) {
        self.inner.ready.store(ready, Ordering::Relaxed)
    }
    pub(crate) fn render_metrics(&self) -> String {
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
        .map(|o| Caller::Owner(auth::Owner::from_digest(o)))
        .collect()
}

/// Loads the built-in scenarios, then every `*.json` in `dir` (a missing directory is fine; an
/// invalid file is an error naming the file and the field).
pub fn preload(state: &AppState, dir: &std::path::Path) -> Result<(), String> {
    for (name, text) in BUILTIN {
        let scenario =
            Scenario::from_json(text).map_err(|e| format!("built-in scenario {name}: {e}"))?;
        state
            .register_scenario(scenario, "builtin", &Caller::Open)
            .map_err(|e| e.problem.detail)?;
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
    for path in files {
        let scenario =
            Scenario::from_file(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let (stored, created) = state
            .register_scenario(scenario, "file", &Caller::Open)
            .map_err(|e| e.problem.detail)?;
        tracing::info!(file = %path.display(), scenario_id = %stored.id, new = created, "scenario loaded");
    }
    Ok(())
}

/// With `--data-dir`: registers the API scenarios recorded there (with their owners) and takes
/// back the finished job records. A record that is damaged, or no longer a valid scenario for
/// this build, is skipped with a warning. The maps are read from disk on demand, and into
/// memory by [`warm_from_disk`].
pub fn restore(state: &AppState) {
    let Some(disk) = &state.inner.disk else {
        return;
    };
    let mut scenarios = 0;
    for (id, record) in disk.load_json::<ScenarioRecord>(store::Kind::Scenario) {
        let parsed = Scenario::from_json(&record.document.to_string());
        let scenario = match parsed {
            Ok(scenario) if scenario.content_hash() == id => scenario,
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
            if let Err(e) = state.register_scenario(scenario.clone(), "api", &owner) {
                tracing::warn!(scenario_id = %id, error = %e.problem.detail, "recorded scenario not registered");
            }
        }
        scenarios += 1;
    }
    let jobs = state.jobs().restore();
    tracing::info!(scenarios, jobs, "restored from the data directory");
}

/// Loads the data directory's maps into memory, newest first, up to the cache's budget.
pub async fn warm_from_disk(state: &AppState) {
    state.cache().warm(state.limits().cache_bytes).await;
}

/// The full application: routes, fallbacks, metrics, authentication, the request timeout,
/// request ids, tracing, CORS (only when origins are configured) and the body limit.
pub fn app(state: AppState) -> axum::Router {
    let max_body = state.limits().max_body_bytes;
    let cors = (!state.inner.cors_origins.is_empty()).then(|| {
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(state.inner.cors_origins.clone()))
            .allow_methods([Method::GET, Method::POST, Method::DELETE])
            .allow_headers([header::CONTENT_TYPE, header::AUTHORIZATION, header::ACCEPT])
            .expose_headers([header::LOCATION, header::RETRY_AFTER])
            .max_age(Duration::from_secs(600))
    });
    let router = api::router()
        .route_layer(middleware::from_fn(track_metrics))
        .fallback(route_not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(max_body))
        .layer(middleware::from_fn_with_state(state.clone(), auth::authenticate))
        .layer(middleware::from_fn_with_state(state.clone(), request_timeout))
        // gzip or brotli when the client accepts it (a 577k-cell map body is 10.9 MB of JSON);
        // tower-http's default predicate leaves PNGs and tiny bodies alone.
        .layer(CompressionLayer::new())
        .layer(
            ServiceBuilder::new()
                .layer(middleware::from_fn(clean_request_id))
                .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
                .layer(TraceLayer::new_for_http().make_span_with(|req: &Request| {
                    let request_id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
                    tracing::info_span!("request", method = %req.method(), uri = %req.uri(), request_id = %request_id)
                }))
                .layer(PropagateRequestIdLayer::x_request_id()),
        );
    let router = match cors {
        Some(cors) => router.layer(cors),
        None => router,
    };
    router.with_state(state)
}

/// Drops a client's `x-request-id` that is too long or has characters that do not belong in a
/// log line; [`SetRequestIdLayer`] then gives the request a fresh UUID.
async fn clean_request_id(mut req: Request, next: Next) -> Response {
    let acceptable = |v: &HeaderValue| {
        let bytes = v.as_bytes();
        !bytes.is_empty()
            && bytes.len() <= MAX_REQUEST_ID_CHARS
            && bytes
                .iter()
                .all(|b| b.is_ascii_alphanumeric() || b"._:-".contains(b))
    };
    if req
        .headers()
        .get("x-request-id")
        .is_some_and(|v| !acceptable(v))
    {
        req.headers_mut().remove("x-request-id");
    }
    next.run(req).await
}

/// Answers 503 when a request takes longer than the request timeout (the handler's future is
/// dropped, which cancels its heavy query, see `queries`).
async fn request_timeout(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let limit = state.limits().request_timeout;
    match tokio::time::timeout(limit, next.run(req)).await {
        Ok(response) => response,
        Err(_) => {
            metrics::counter!("irs_request_timeouts_total").increment(1);
            ApiError::request_timeout(limit.as_secs()).into_response()
        }
    }
}

async fn route_not_found(State(_): State<AppState>, req: Request) -> Response {
    metrics::counter!("http_requests_total", "route" => "unmatched", "method" => req.method().to_string(), "status" => "404").increment(1);
    ApiError::route_not_found(req.uri().path()).into_response()
}

async fn method_not_allowed() -> Response {
    ApiError::method_not_allowed().into_response()
}

async fn track_metrics(req: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched".to_string(), |m| m.as_str().to_string());
    let method = req.method().to_string();
    let response = next.run(req).await;
    let status = response.status().as_u16().to_string();
    metrics::counter!("http_requests_total", "route" => route.clone(), "method" => method, "status" => status).increment(1);
    metrics::histogram!("http_request_duration_seconds", "route" => route)
        .record(started.elapsed().as_secs_f64());
    response
}

fn init_tracing(format: LogFormat) {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| EnvFilter::new("info,tower_http=info"));
    // Colour codes only on a terminal: log files and collectors get plain text.
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_writer(std::io::stderr);
    let _ = match format {
        LogFormat::Text => builder.try_init(),
        LogFormat::Json => builder.json().flatten_event(true).try_init(),
    };
}

async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = terminate => {},
    }
}

/// After the accept loop stopped: waits up to `grace` for running jobs and open requests, then
/// cancels the jobs still running and gives connections two more seconds.
async fn drain(state: &AppState, connections: &server::OpenConnections, grace: Duration) {
    let started = Instant::now();
    let deadline = started + grace;
    let live = state.jobs().live().len();
    tracing::info!(
        live_jobs = live,
        connections = connections.count(),
        grace_s = grace.as_secs_f64(),
        "shutdown: no longer accepting; waiting for running work"
    );
    while !state.jobs().live().is_empty() && Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let cancelled = state.jobs().cancel_all();
    if cancelled.is_empty() {
        tracing::info!(
            waited_s = started.elapsed().as_secs_f64(),
            "shutdown: no job left running"
        );
    } else {
        tracing::warn!(
            cancelled = cancelled.len(),
            job_ids = %cancelled.join(","),
            "shutdown: grace period over; cancelled the jobs still queued or running"
        );
    }
    // Jobs check their flag once per grid row, so they end within a fraction of a second;
    // requests waiting on them are then answered and their connections close.
    let open = connections
        .drain(Instant::now().max(deadline) + Duration::from_secs(2))
        .await;
    if open > 0 {
        tracing::warn!(
            connections = open,
            "shutdown: closing connections still open"
        );
    }
    tracing::info!(
        total_s = started.elapsed().as_secs_f64(),
        "shutdown complete"
    );
}

/// Why `serve` stopped with an error.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ServeError {
    /// What the operator gave is wrong: a scenario file in the scenarios directory is invalid.
    #[error("{0}")]
    Config(String),
    /// The service could not run: the address is taken, the runtime or the metrics recorder
    /// could not start, or serving failed.
    #[error("{0}")]
    Runtime(String),
}

/// `irs-planner serve`: runs until SIGINT/SIGTERM. Prints `listening on http://ADDR` on stdout
/// once bound (with `--bind …:0`, the port chosen).
pub fn run(args: ServeArgs) -> Result<(), ServeError> {
    let runtime_error = |e: &dyn std::fmt::Display| ServeError::Runtime(e.to_string());
    init_tracing(args.log_format);
    let metrics = PrometheusBuilder::new()
        .set_buckets(&[
            0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0,
            30.0, 60.0,
        ])
        .map_err(|e| runtime_error(&e))?
        .install_recorder()
        .map_err(|e| runtime_error(&format!("metrics recorder: {e}")))?;
    // Map builds' parallel loops run on rayon's global pool: built here so that its threads
    // start at the workers' lower priority (see `priority`).
    if let Err(e) = rayon::ThreadPoolBuilder::new()
        .thread_name(|k| format!("irs-build-{k}"))
        .start_handler(|_| priority::lower_this_thread())
        .build_global()
    {
        tracing::warn!(error = %e, "the build pool was already started: builds keep the default priority");
    }
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| runtime_error(&e))?;
    let grace = Duration::from_secs(args.shutdown_grace_s);
    let outcome = runtime.block_on(async move {
        let state = AppState::new(&args, metrics).map_err(ServeError::Config)?;
        preload(&state, &args.scenarios).map_err(ServeError::Config)?;
        restore(&state);
        let listener = tokio::net::TcpListener::bind(args.bind)
            .await
            .map_err(|e| runtime_error(&format!("--bind {}: {e}", args.bind)))?;
        let addr = listener.local_addr().map_err(|e| runtime_error(&e))?;
        state.set_ready(true);
        tracing::info!(
            %addr,
            workers = args.workers(),
            queue = args.queue,
            query_workers = args.query_workers(),
            cache_mb = args.cache_mb,
            authentication = state.tokens().enabled(),
            tokens = state.tokens().count(),
            "irs-planner listening"
        );
        println!("listening on http://{addr}");
        let limits = server::ConnectionLimits {
            max_connections: args.max_connections,
            header_timeout: Duration::from_secs(args.header_timeout_s.max(1)),
            idle_timeout: Duration::from_secs(args.idle_timeout_s.max(1)),
        };
        let warming = state.clone();
        tokio::spawn(async move { warm_from_disk(&warming).await });
        if let Some(cluster) = state.cluster().cloned() {
            let health = cluster.clone();
            tokio::spawn(async move { health.watch_health().await });
            tokio::spawn(cluster::run_builder(state.clone(), cluster.clone()));
            tracing::info!(replica = %cluster.replica, "sharing scenarios, maps and jobs through Redis");
        }
        let stopping = state.clone();
        let connections = server::serve(listener, app(state.clone()), limits, async move {
            shutdown_signal().await;
            stopping.set_ready(false);
        })
        .await;
        drain(&state, &connections, grace).await;
        Ok(())
    });
    // Blocking tasks still running (a build between two cancellation checks) are not waited
    // for beyond this: the process must exit within the grace period plus two seconds.
    runtime.shutdown_timeout(Duration::from_millis(500));
    outcome
}
