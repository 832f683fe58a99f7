//! The `fleet` command: several robots planned at once on the scenario's gain map (the body of
//! `POST /v1/fleet-plans`), the robots read from a JSON file.

use super::{Failure, MapArgs, build_map, load_scenario, print_json, write_png};
use clap::Args;
use irs_answers::files::{MAX_SCENARIO_FILE_BYTES, read_regular_text};
use irs_answers::fleet::{self, FleetQuery};
use irs_answers::render::RenderOptions;
use irs_answers::timing::Timed;
use irs_model::input::parse_finite;
use irs_model::radiomap::{MapKind, Progress, WorkError};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Debug, Args)]
pub struct FleetArgs {
    #[command(flatten)]
    pub map: MapArgs,
    /// The robots, as the body of POST /v1/fleet-plans without its map: {"robots": [{"start":
    /// [x, y], "goal": [x, y], "threshold": t}, …], "unit": …, "dt_s": …, "horizon_s": …},
    /// in priority order.
    #[arg(long, value_name = "FILE")]
    pub robots: PathBuf,
    /// With --png: a tick on every route every this many seconds.
    #[arg(long, value_name = "SECONDS", default_value = "10", value_parser = parse_finite)]
    pub tick_s: f64,
}

/// `irs-planner fleet …`.
pub fn run_fleet(args: &FleetArgs) -> Result<(), Failure> {
    if args.map.kind != MapKind::Gain {
        return Err(Failure::input(
            "--kind: fleet plans run on gain maps (robots sharing an AP are given \"access\" in the robots file)",
        ));
    }
    if args.tick_s <= 0.0 {
        return Err(Failure::input(
            "--tick-s: must be a positive number of seconds",
        ));
    }
    let file = args.robots.display();
    let text = read_regular_text(&args.robots, MAX_SCENARIO_FILE_BYTES)
        .map_err(|e| Failure::input(format!("--robots {file}: {e}")))?;
    let query: FleetQuery =
        serde_json::from_str(&text).map_err(|e| Failure::input(format!("--robots {file}: {e}")))?;
    let scenario = load_scenario(&args.map.source)?;
    let map = build_map(&args.map, &scenario)?;
    let started = Instant::now();
    let answer =
        fleet::plan(&scenario, &map, &query, &Progress::default()).map_err(|e| match e {
            WorkError::Invalid(e) => {
                Failure::input(format!("--robots {file}: {}: {}", e.field, e.reason))
            }
            WorkError::Cancelled(c) => Failure::runtime(c.to_string()),
        })?;
    write_png(
        &args.map,
        &map,
        &scenario,
        RenderOptions::for_fleet(&answer.plan, args.tick_s),
    )?;
    print_json(&Timed::since(started, answer))
}
