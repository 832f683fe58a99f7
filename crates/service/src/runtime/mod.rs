//! Running the service: [`run`] serves one [`App`] on a listener until a shutdown future
//! resolves, then drains. It installs nothing process-wide: the metrics registry is the
//! server's own ([`Metrics`]), and no tracing subscriber or rayon pool is set up inside it, so
//! tests start servers in-process, several per process. [`serve`] is the process's entry
//! (`irs-planner serve`): it installs the tracing subscriber and the build pool, binds, and
//! runs until SIGINT/SIGTERM. [`server`] is the accept loop and its timeouts.

pub(crate) mod series;
pub(crate) mod server;

use crate::app::{self, App};
use crate::config::{LogFormat, ServeArgs};
use crate::tasks::{self, Metrics};
use crate::{http, priority};
use std::future::Future;
use std::time::{Duration, Instant};
use tokio::net::TcpListener;

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
    // requests waiting on them are then answered and their connections close. Each records
    // how it ended (with a data directory, an interrupted map build as queued, to resume)
    // before it leaves the live set, and a cluster build's task stores its checkpoint after:
    // wait for both, so no record or checkpoint is lost with the process. Both waits share
    // the last two seconds, so the exit stays within the grace plus two.
    let end = Instant::now().max(deadline) + Duration::from_secs(2);
    while (!state.jobs().live().is_empty() || state.shared_builds() > 0) && Instant::now() < end {
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let open = connections.drain(end).await;
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
    /// What the operator gave is wrong: a setting (a CORS origin, a token file, a data
    /// directory that cannot be created).
    #[error("{0}")]
    Config(String),
    /// The service could not run: the address is taken, the runtime or the metrics registry
    /// could not start, or serving failed.
    #[error("{0}")]
    Runtime(String),
}

/// Cancels the jobs still live when [`run`]'s future is dropped before it drained (a test's
/// runtime going away): builds stop at their next row instead of holding the blocking pool.
struct CancelJobsOnDrop(App);

impl Drop for CancelJobsOnDrop {
    fn drop(&mut self) {
        self.0.jobs().cancel_all();
    }
}

/// Serves the service configured by `args` on `listener` until `shutdown` resolves, then (not
/// ready, still serving) waits `--shutdown-delay-s`, stops accepting, waits up to
/// `--shutdown-grace-s` for running jobs and requests, cancels the rest and returns. Prints `listening on http://ADDR` on stdout once it serves. Dropping the
/// future before then cancels the server's jobs.
pub async fn run(
    listener: TcpListener,
    args: ServeArgs,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServeError> {
    let metrics = Metrics::new().map_err(ServeError::Runtime)?;
    metrics
        .clone()
        .scope(serve_app(listener, args, metrics, shutdown))
        .await
}

/// How often the data directory's write probe runs: a tiny file written, flushed and removed,
/// cheap enough to run often and soon enough for a readiness probe polled every few seconds.
const DATA_DIR_PROBE_EVERY: Duration = Duration::from_secs(5);

async fn serve_app(
    listener: TcpListener,
    args: ServeArgs,
    metrics: Metrics,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> Result<(), ServeError> {
    let runtime_error = |e: &dyn std::fmt::Display| ServeError::Runtime(e.to_string());
    let grace = Duration::from_secs(args.shutdown_grace_s);
    let delay = Duration::from_secs(args.shutdown_delay_s);
    // First, as before the split: an operator sees the same error first.
    let cors_origins = http::cors_origins(&args.cors_origin).map_err(ServeError::Config)?;
    let state = App::new(&args, metrics.handle()).map_err(ServeError::Config)?;
    let _cancel = CancelJobsOnDrop(state.clone());
    app::preload(&state, &args.scenarios).map_err(ServeError::Config)?;
    app::restore(&state).await;
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
        write_timeout: Duration::from_secs(args.write_timeout_s.max(1)),
        per_client: args.max_connections_per_client,
        max_streams: args.max_streams.max(1),
    };
    let warming = state.clone();
    let mut background = vec![tasks::spawn(
        async move { app::warm_from_disk(&warming).await },
    )];
    if let Some(dir) = state.data_dir().cloned() {
        // `/readyz` reports a data directory that cannot be written (full, read-only) from
        // this probe's last answer; a failed write reports it at once too (store::disk).
        background.push(tasks::spawn(async move {
            loop {
                tokio::time::sleep(DATA_DIR_PROBE_EVERY).await;
                let dir = dir.clone();
                let _ = tasks::spawn_blocking(move || dir.probe()).await;
            }
        }));
    }
    // The registry's histograms are drained into their buckets now and then, as the
    // process-wide exporter's upkeep thread would.
    let upkeep = metrics.handle();
    background.push(tasks::spawn(async move {
        loop {
            tokio::time::sleep(Duration::from_secs(5)).await;
            upkeep.run_upkeep();
        }
    }));
    if let Some(cluster) = state.build_stream().cloned() {
        let health = cluster.clone();
        background.push(tasks::spawn(async move { health.watch_health().await }));
        background.push(tasks::spawn(app::builder::run(
            state.clone(),
            cluster.clone(),
        )));
        background.push(tasks::spawn(app::deletions::follow(
            state.clone(),
            cluster.clone(),
        )));
        tracing::info!(replica = %cluster.replica, "sharing scenarios, maps and jobs through Redis");
    }
    let stopping = state.clone();
    let connections = server::serve(
        listener,
        http::app(
            state.clone(),
            cors_origins,
            http::delivery::Budget::new(args.answers_in_flight_mb.saturating_mul(1 << 20)),
        ),
        limits,
        async move {
            shutdown.await;
            stopping.set_ready(false);
            if !delay.is_zero() {
                tracing::info!(
                    delay_s = delay.as_secs(),
                    "shutdown: not ready; serving until the load balancer lets go"
                );
                tokio::time::sleep(delay).await;
            }
        },
    )
    .await;
    drain(&state, &connections, grace).await;
    for task in background {
        task.abort();
    }
    Ok(())
}

/// `irs-planner serve`: the process's entry. Installs the tracing subscriber and the build
/// pool, starts the runtime, binds `--bind` and [`run`]s until SIGINT/SIGTERM.
pub fn serve(args: ServeArgs) -> Result<(), ServeError> {
    let runtime_error = |e: &dyn std::fmt::Display| ServeError::Runtime(e.to_string());
    init_tracing(args.log_format);
    crate::memory::return_large_blocks();
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
    let outcome = runtime.block_on(async move {
        let listener = TcpListener::bind(args.bind)
            .await
            .map_err(|e| runtime_error(&format!("--bind {}: {e}", args.bind)))?;
        run(listener, args, shutdown_signal()).await
    });
    // Blocking tasks still running (a build between two cancellation checks) are not waited
    // for beyond this: the process must exit within the grace period plus two seconds.
    runtime.shutdown_timeout(Duration::from_millis(500));
    outcome
}
