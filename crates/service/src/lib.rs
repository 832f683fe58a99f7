//! The HTTP planning service: axum on tokio, maps cached in moka, builds on a bounded blocking
//! pool, `tracing` spans per request and per job, Prometheus metrics. The contract is
//! `openapi.yaml`.
//!
//! Layout: [`config`] (flags and environment), [`http`] (the route table, one module of
//! handlers per resource, the middleware stack, problem+json answers with [`Problem`] the body
//! of every error answer, authentication at the door), `app` (the application's own error type and
//! identity: tokens, owners, callers), `cache` (scenario registry, map cache and the maps'
//! widest-path indexes), `answers` (path answers kept for repeated queries), `jobs` (map builds
//! and placement searches), `queries` (admission of heavy queries), `server` (the accept loop
//! and its timeouts), `store` (the data directory of `--data-dir`), `cluster` (replicas sharing
//! Redis, `--redis-url`), `viewer` (the built-in map viewer at `/`).

pub(crate) mod answers;

pub mod app;
pub(crate) mod cache;
pub(crate) mod cluster;
pub mod config;
pub mod http;
pub(crate) mod jobs;
pub(crate) mod priority;
pub mod probe;
pub(crate) mod queries;
pub(crate) mod server;
pub(crate) mod store;
pub(crate) mod viewer;

pub use app::App;
pub use http::problem::Problem;

use config::{LogFormat, ServeArgs};
use metrics_exporter_prometheus::PrometheusBuilder;
use std::time::{Duration, Instant};

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
async fn drain(state: &App, connections: &server::OpenConnections, grace: Duration) {
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
        let state = App::new(&args, metrics).map_err(ServeError::Config)?;
        app::preload(&state, &args.scenarios).map_err(ServeError::Config)?;
        app::restore(&state);
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
        tokio::spawn(async move { app::warm_from_disk(&warming).await });
        if let Some(cluster) = state.cluster().cloned() {
            let health = cluster.clone();
            tokio::spawn(async move { health.watch_health().await });
            tokio::spawn(cluster::run_builder(state.clone(), cluster.clone()));
            tracing::info!(replica = %cluster.replica, "sharing scenarios, maps and jobs through Redis");
        }
        let stopping = state.clone();
        let connections = server::serve(listener, http::app(state.clone()), limits, async move {
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
