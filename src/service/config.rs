//! Service settings: every one a flag and an environment variable (README "Configuration").

use clap::{Args, ValueEnum};
use std::net::SocketAddr;
use std::path::PathBuf;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

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
}

impl ServeArgs {
    pub fn workers(&self) -> usize {
        self.workers
            .unwrap_or_else(|| std::thread::available_parallelism().map_or(2, |n| n.get()))
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
