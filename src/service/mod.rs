//! The HTTP planning service: axum on tokio, maps cached in moka, builds on a bounded blocking
//! pool, `tracing` spans per request and per job, Prometheus metrics. The contract is
//! `openapi.yaml`.
//!
//! Layout: [`config`] (flags and environment), [`api`] (routes and handlers), `cache` (scenario
//! registry and map cache), `jobs` (map builds), `errors` (problem+json; [`Problem`] is the
//! body of every error answer), `viewer` (the built-in map viewer at `/`).

pub mod api;
pub(crate) mod cache;
pub mod config;
pub(crate) mod errors;
pub(crate) mod jobs;
pub(crate) mod viewer;

pub use errors::Problem;

use crate::scenario::{BUILTIN, Scenario};
use axum::extract::{DefaultBodyLimit, MatchedPath, Request, State};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use cache::{MapCache, ScenarioRegistry};
use config::{LogFormat, ServeArgs};
use errors::ApiError;
use jobs::Jobs;
use metrics_exporter_prometheus::{PrometheusBuilder, PrometheusHandle};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;
use tower::ServiceBuilder;
use tower_http::compression::CompressionLayer;
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
}

/// Shared state of the handlers.
#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    limits: Limits,
    registry: ScenarioRegistry,
    cache: MapCache,
    jobs: Arc<Jobs>,
    ready: AtomicBool,
    metrics: PrometheusHandle,
}

impl AppState {
    pub fn new(args: &ServeArgs, metrics: PrometheusHandle) -> Self {
        AppState {
            inner: Arc::new(Inner {
                limits: Limits {
                    max_body_bytes: args.max_body_kb * 1024,
                    sync_cells: args.sync_cells,
                    max_rate_cells: args.max_rate_cells,
                    max_sweep: args.max_sweep,
                    max_draws: args.max_draws.min(crate::montecarlo::MAX_DRAWS),
                },
                registry: ScenarioRegistry::new(args.max_scenarios),
                cache: MapCache::new(args.cache_mb * 1024 * 1024),
                jobs: Arc::new(Jobs::new(args.workers(), args.queue, args.job_history)),
                ready: AtomicBool::new(false),
                metrics,
            }),
        }
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
    pub(crate) fn jobs(&self) -> &Arc<Jobs> {
        &self.inner.jobs
    }
    /// Registers a scenario, evicting the least recently used unneeded one if the registry is
    /// full (see [`ScenarioRegistry`]).
    pub(crate) fn register_scenario(
        &self,
        scenario: Scenario,
        source: &'static str,
    ) -> Result<(Arc<cache::StoredScenario>, bool), ApiError> {
        self.registry().register(scenario, source, || {
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

/// Loads the built-in scenarios, then every `*.json` in `dir` (a missing directory is fine; an
/// invalid file is an error naming the file and the field).
pub fn preload(state: &AppState, dir: &std::path::Path) -> Result<(), String> {
    for (name, text) in BUILTIN {
        let scenario =
            Scenario::from_json(text).map_err(|e| format!("built-in scenario {name}: {e}"))?;
        state
            .register_scenario(scenario, "builtin")
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
            .register_scenario(scenario, "file")
            .map_err(|e| e.problem.detail)?;
        tracing::info!(file = %path.display(), scenario_id = %stored.id, new = created, "scenario loaded");
    }
    Ok(())
}

/// The full application: routes, fallbacks, metrics, request ids, tracing and the body limit.
pub fn app(state: AppState) -> axum::Router {
    let max_body = state.limits().max_body_bytes;
    api::router()
        .route_layer(middleware::from_fn(track_metrics))
        .fallback(route_not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(max_body))
        // gzip or brotli when the client accepts it (a 577k-cell map body is 10.9 MB of JSON);
        // tower-http's default predicate leaves PNGs and tiny bodies alone.
        .layer(CompressionLayer::new())
        .layer(
            ServiceBuilder::new()
                .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
                .layer(TraceLayer::new_for_http().make_span_with(|req: &Request| {
                    let request_id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
                    tracing::info_span!("request", method = %req.method(), uri = %req.uri(), request_id = %request_id)
                }))
                .layer(PropagateRequestIdLayer::x_request_id()),
        )
        .with_state(state)
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
    tracing::info!("shutdown signal received; draining connections");
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
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| runtime_error(&e))?;
    runtime.block_on(async move {
        let state = AppState::new(&args, metrics);
        preload(&state, &args.scenarios).map_err(ServeError::Config)?;
        let listener = tokio::net::TcpListener::bind(args.bind)
            .await
            .map_err(|e| runtime_error(&format!("--bind {}: {e}", args.bind)))?;
        let addr = listener.local_addr().map_err(|e| runtime_error(&e))?;
        state.set_ready(true);
        tracing::info!(%addr, workers = args.workers(), queue = args.queue, cache_mb = args.cache_mb, "irs-planner listening");
        println!("listening on http://{addr}");
        let ready = state.clone();
        axum::serve(listener, app(state))
            .with_graceful_shutdown(async move {
                shutdown_signal().await;
                ready.set_ready(false);
            })
            .await
            .map_err(|e| runtime_error(&e))
    })
}
