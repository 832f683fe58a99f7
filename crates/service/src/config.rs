//! Service settings: every one a flag and an environment variable (README "Configuration").

use clap::{Args, ValueEnum};
use std::net::SocketAddr;
use std::path::PathBuf;

/// How log lines are written (`--log-format`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    /// Human-readable lines with their fields.
    Text,
    /// One JSON object a line, for log collectors.
    Json,
}

/// The server's settings: the flags of `irs-planner serve`, each also an `IRS_*` variable.
#[derive(Debug, Clone, Args)]
pub struct ServeArgs {
    /// Address to listen on (port 0 picks a free port, printed at start-up).
    #[arg(long, env = "IRS_BIND", default_value = "127.0.0.1:8080")]
    pub bind: SocketAddr,
    /// Directory of scenario JSON files to preload, in addition to the built-in ones.
    #[arg(long, env = "IRS_SCENARIOS", default_value = "scenarios")]
    pub scenarios: PathBuf,
    /// Map cache budget in MiB (maps are weighed by their size in memory).
    #[arg(long, env = "IRS_CACHE_MB", default_value_t = 512)]
    pub cache_mb: u64,
    /// Budget in MiB of the path answers kept for repeated queries (a 41-waypoint answer of
    /// the paper floor is 21 kB); 0 keeps none.
    #[arg(long, env = "IRS_ANSWER_CACHE_MB", default_value_t = 32)]
    pub answer_cache_mb: u64,
    /// Keep API scenarios, built maps and finished job records in this directory, so they
    /// survive a restart (created if missing). Without it everything lives in memory only.
    #[arg(long, env = "IRS_DATA_DIR")]
    pub data_dir: Option<PathBuf>,
    /// Share scenarios, maps and jobs with the other replicas through this Redis
    /// (`redis://host:port/db`): any replica answers for any of them, and each map is built
    /// once in the cluster. Without it the replica is on its own.
    #[arg(long, env = "IRS_REDIS_URL")]
    pub redis_url: Option<String>,
    /// With `--redis-url`: the budget in MiB of the maps stored in Redis, shared by every
    /// replica; storing one past it evicts the least recently used (built again on request).
    /// Keep Redis's `maxmemory` above it, with `maxmemory-policy noeviction`.
    #[arg(long, env = "IRS_REDIS_MAPS_MB", default_value_t = 1024)]
    pub redis_maps_mb: u64,
    /// Disk budget of the data directory's maps in MiB; past it the least recently written
    /// maps are deleted (they are built again on request).
    #[arg(long, env = "IRS_DATA_MAPS_MB", default_value_t = 4096)]
    pub data_maps_mb: u64,
    /// Map builds that may run at once on the blocking pool (default: the number of cores).
    #[arg(long, env = "IRS_WORKERS")]
    pub workers: Option<usize>,
    /// Map builds that may wait for a worker; one more is refused with 503 and Retry-After.
    #[arg(long, env = "IRS_QUEUE", default_value_t = 16)]
    pub queue: usize,
    /// Log format on stderr.
    #[arg(long, env = "IRS_LOG_FORMAT", value_enum, default_value = "text")]
    pub log_format: LogFormat,
    /// Largest request body in KiB (413 above). A floor plan travels inside the scenario as
    /// base64: the warehouse's 1200 × 800 PGM is 1.3 MB of it, a 4096² map 22 MB.
    #[arg(long, env = "IRS_MAX_BODY_KB", default_value_t = 8192)]
    pub max_body_kb: usize,
    /// Largest body of `POST /v1/scenarios` in KiB (413 above; never below `--max-body-kb`):
    /// registering a scenario is how a floor plan up to the model's 4096² pixels arrives,
    /// 22.4 MB of base64 for an 8-bit PGM. Inline scenarios elsewhere keep `--max-body-kb`.
    #[arg(long, env = "IRS_MAX_SCENARIO_BODY_KB", default_value_t = 24 * 1024)]
    pub max_scenario_body_kb: usize,
    /// Largest number of registered scenarios (507 above).
    #[arg(long, env = "IRS_MAX_SCENARIOS", default_value_t = 1000)]
    pub max_scenarios: usize,
    /// Gain maps with at most this many cells are built while the request waits (200); larger
    /// maps and every rate map are built as jobs (202).
    #[arg(long, env = "IRS_SYNC_CELLS", default_value_t = 250_000)]
    pub sync_cells: usize,
    /// Largest grid (cells) for which rate maps are built: each free cell runs the solver and
    /// its certificate (about 2 ms of CPU per cell at N = 60).
    #[arg(long, env = "IRS_MAX_RATE_CELLS", default_value_t = 40_000)]
    pub max_rate_cells: usize,
    /// Largest number of thresholds in one sweep.
    #[arg(long, env = "IRS_MAX_SWEEP", default_value_t = 1000)]
    pub max_sweep: usize,
    /// Largest number of Monte Carlo draws per waypoint in a path query.
    #[arg(long, env = "IRS_MAX_DRAWS", default_value_t = 100_000)]
    pub max_draws: usize,
    /// Finished jobs kept for inspection (oldest forgotten first).
    #[arg(long, env = "IRS_JOB_HISTORY", default_value_t = 1000)]
    pub job_history: usize,
    /// Memory in MiB the finished jobs' answers may hold (a placement's ranking is megabytes);
    /// past it the oldest finished jobs are forgotten, whatever `--job-history` allows.
    #[arg(long, env = "IRS_JOB_HISTORY_MB", default_value_t = 64)]
    pub job_history_mb: u64,
    /// Memory budget of the scenario registry in MiB (scenarios weighed by their canonical
    /// document and decoded floor plan; least recently used API scenarios evicted, 507 when
    /// nothing can go).
    #[arg(long, env = "IRS_REGISTRY_MB", default_value_t = 256)]
    pub registry_mb: u64,
    /// Largest estimated CPU time (seconds of one core) of one map build or placement search;
    /// a request above it is refused with 422 before any work starts.
    #[arg(long, env = "IRS_MAX_BUILD_CPU_S", default_value_t = 600.0)]
    pub max_build_cpu_s: f64,
    /// Largest estimated CPU time (seconds of one core) of one Monte Carlo check of a path.
    #[arg(long, env = "IRS_MAX_CHECK_CPU_S", default_value_t = 60.0)]
    pub max_check_cpu_s: f64,
    /// Heavy queries (sweeps, paths and pictures of big maps, map bodies and exports, Monte
    /// Carlo checks) that may run at once, on a thread pool of their own so they never hold
    /// the async threads or the map builders' pool (default: one a core).
    #[arg(long, env = "IRS_QUERY_WORKERS")]
    pub query_workers: Option<usize>,
    /// Heavy queries that may wait for a query worker; one more is refused with 503 and
    /// Retry-After.
    #[arg(long, env = "IRS_QUERY_QUEUE", default_value_t = 32)]
    pub query_queue: usize,
    /// Seconds a client has to send a request's headers (on a new or a kept-alive connection).
    #[arg(long, env = "IRS_HEADER_TIMEOUT_S", default_value_t = 10)]
    pub header_timeout_s: u64,
    /// Seconds a client has to send a request's body once its headers arrived (408 after).
    #[arg(long, env = "IRS_BODY_TIMEOUT_S", default_value_t = 30)]
    pub body_timeout_s: u64,
    /// Seconds a connection with no request in flight and no answer going out stays open
    /// (HTTP/2 PINGs do not keep it open).
    #[arg(long, env = "IRS_IDLE_TIMEOUT_S", default_value_t = 60)]
    pub idle_timeout_s: u64,
    /// Seconds an answer may make no progress (its client stopped reading) before its
    /// connection is closed and the answer's memory freed.
    #[arg(long, env = "IRS_WRITE_TIMEOUT_S", default_value_t = 30)]
    pub write_timeout_s: u64,
    /// Memory in MiB that answers being sent may hold at once (answers under 64 KiB aside); an
    /// answer that would exceed it is answered 503 with Retry-After instead.
    #[arg(long, env = "IRS_ANSWERS_IN_FLIGHT_MB", default_value_t = 256)]
    pub answers_in_flight_mb: u64,
    /// Seconds one request may take from its headers to its answer (503 after; long builds
    /// run as jobs, so only a stuck request reaches it).
    #[arg(long, env = "IRS_REQUEST_TIMEOUT_S", default_value_t = 120)]
    pub request_timeout_s: u64,
    /// Connections served at once; further ones wait in the kernel's accept queue.
    #[arg(long, env = "IRS_MAX_CONNECTIONS", default_value_t = 1024)]
    pub max_connections: usize,
    /// Connections one client address may hold at once; more are closed as they arrive. Behind
    /// a proxy every client has the proxy's address: set it to at least the proxy's
    /// connections to this server there, and limit clients at the proxy.
    #[arg(long, env = "IRS_MAX_CONNECTIONS_PER_CLIENT", default_value_t = 256)]
    pub max_connections_per_client: usize,
    /// HTTP/2 streams (requests) one connection may have open at once.
    #[arg(long, env = "IRS_MAX_STREAMS", default_value_t = 32)]
    pub max_streams: u32,
    /// Bearer tokens, comma-separated: when any is set (here or in --api-tokens-file), every
    /// mutating request needs one, and jobs and API scenarios belong to the token that made
    /// them. Off by default (the embedded development set-up).
    #[arg(
        long,
        env = "IRS_API_TOKENS",
        value_delimiter = ',',
        hide_env_values = true
    )]
    pub api_tokens: Vec<String>,
    /// A file of bearer tokens, one per line (blank lines and `#` comments ignored).
    #[arg(long, env = "IRS_API_TOKENS_FILE")]
    pub api_tokens_file: Option<PathBuf>,
    /// Origins allowed to call the API from a browser (CORS), comma-separated; none by default
    /// (the built-in viewer is same-origin).
    #[arg(long, env = "IRS_CORS_ORIGINS", value_delimiter = ',')]
    pub cors_origin: Vec<String>,
    /// Seconds SIGTERM waits for running jobs before cancelling them; the process exits at most
    /// two seconds later.
    #[arg(long, env = "IRS_SHUTDOWN_GRACE_S", default_value_t = 5)]
    pub shutdown_grace_s: u64,
    /// Seconds SIGTERM keeps serving, with `/readyz` answering 503, before it stops accepting:
    /// behind a load balancer, long enough for its health check to take the replica out (two
    /// failed checks), so no request is sent to a replica that has closed. 0 (the default)
    /// stops accepting at once, as a lone server should.
    #[arg(long, env = "IRS_SHUTDOWN_DELAY_S", default_value_t = 0)]
    pub shutdown_delay_s: u64,
}

impl ServeArgs {
    /// Map-build workers: `--workers`, else one a core.
    pub fn workers(&self) -> usize {
        self.workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()))
            .max(1)
    }

    /// Heavy-query workers: `--query-workers`, else one a core. A path query on a large map
    /// is a fraction of a millisecond of search and about as much of writing; with half the cores, the
    /// 1001² floor's random path queries left a core idle (1 037–1 150 req/s on 2 cores against
    /// 1 287–1 421 with both, `DISTINCT=random RESOLUTION=0.02 scripts/load.sh`).
    pub fn query_workers(&self) -> usize {
        self.query_workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
            .max(1)
    }
}

impl Default for ServeArgs {
    fn default() -> Self {
        use clap::Parser;
        #[derive(Parser)]
        struct Wrapper {
            #[command(flatten)]
            args: ServeArgs,
        }
        Wrapper::parse_from(["irs-planner"]).args
    }
}
