//! The command line: `serve` (the default), `map`, `plan`, `export` and `scenario`. `map` and
//! `plan` print exactly the JSON bodies the API returns; `export` writes Nav2 masks and a NumPy
//! array of a map; `scenario` prints a scenario file in the self-contained form the API takes
//! (a floor plan's map file read and inlined). Bad input exits with code 2 and a message naming the offending
//! field; a `plan` with no path meeting the threshold prints its answer (with the `reason`) and
//! exits with code 3; a failure that is not the input's (the server cannot bind, a file cannot
//! be written) exits with code 1.

mod fleet_args;
mod graph_args;
mod vda5050_args;

use clap::{Args, Parser, Subcommand};
pub use fleet_args::{FleetArgs, run_fleet};
pub use graph_args::{GraphArgs, RoadmapArgs, run_graph, run_roadmap};
use irs_answers::export::{self, MaskKind};
use irs_answers::path::{self, CheckedPath, FrameId};
use irs_answers::phase_text::{PhaseFormat, PhasePrecision};
use irs_answers::render::{self, RenderOptions};
use irs_answers::route::{self, RouteFormat};
use irs_answers::scenario::{Document, ScenarioDocument};
use irs_answers::timing::{self, Timed};
use irs_answers::vda5050;
use irs_model::input::{FieldError, parse_finite, parse_point};
use irs_model::montecarlo::MAX_DRAWS;
use irs_model::phases::PhaseMode;
use irs_model::placement::{self, Candidates, Objective, Pose, Search, Segment, What};
use irs_model::planner::{self, PathShape, Threshold};
use irs_model::radiomap::{MapKey, MapKind, Progress, RadioMap, Unit, WorkError, cost};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;
use irs_model::solver::SolverKind;
use irs_service::config::ServeArgs;
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant, SystemTime};
use vda5050_args::vda_flag;
pub use vda5050_args::{OrderArgs, ZonesArgs, run_zones};

#[derive(Debug, Parser)]
#[command(
    name = "irs-planner",
    version,
    about = "IRS-enhanced indoor robot path planning: radio maps and communication-aware paths"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Run the HTTP planning service (the default when no command is given).
    Serve(ServeArgs),
    /// Compute a radio map and print its JSON body.
    Map(MapArgs),
    /// Plan a path on a radio map and print the path JSON body.
    Plan(PlanArgs),
    /// Write a map's Nav2 keep-out and cost masks (PGM + YAML) and its values (.npy) to a folder.
    Export(ExportArgs),
    /// Print what building a map would cost, as the server estimates it before admitting the
    /// build: `{"cpu_s", "bytes"}` (one core's seconds; the cache's weight), without building.
    Estimate(MapArgs),
    /// Print a scenario file as the self-contained JSON document the API takes (POST
    /// /v1/scenarios): a floor plan's map YAML and image read and inlined.
    Scenario(ScenarioArgs),
    /// Print the map at a threshold as a VDA 5050 zone set: BLOCKED where a free cell is below
    /// it, PENALTY (with --penalty-band) where it meets it narrowly.
    Zones(ZonesArgs),
    /// Score the scenario's route graph (Nav2 GeoJSON or Open-RMF nav graph) on its map: each
    /// edge's worst value, where, its serving APs and whether it crosses an obstacle; at a
    /// threshold, the edges to close.
    Graph(GraphArgs),
    /// Make a route graph of the map's free region (at --threshold, its feasible region): nodes
    /// every --spacing-m metres, lanes to their neighbours wherever open; Nav2 GeoJSON or Open-RMF
    /// YAML, scored, ready to attach as a scenario's route_graph.
    Roadmap(RoadmapArgs),
    /// Plan several robots at once on the scenario's gain map, every robot's requirement held
    /// at every time step with the IRSs shared (docs/model.md §6.5); print the plan (the body of
    /// POST /v1/fleet-plans).
    Fleet(FleetArgs),
    /// Rank candidate poses of an IRS (or positions of the AP) by an objective on their gain
    /// maps and print the ranking (the body of POST /v1/placements).
    Place(PlaceArgs),
    /// GET a running server's health endpoint (for a container's HEALTHCHECK): exit 0 on a
    /// 2xx answer, 1 on anything else or no answer within the timeout.
    Healthcheck(HealthcheckArgs),
}

#[derive(Debug, Args)]
pub struct HealthcheckArgs {
    /// The server's listening address, as `serve --bind` took it (0.0.0.0 is probed on
    /// loopback).
    #[arg(long, env = "IRS_BIND", default_value = "127.0.0.1:8080")]
    pub bind: std::net::SocketAddr,
    /// The endpoint: /healthz (the process answers) or /readyz (it takes traffic).
    #[arg(long, default_value = "/healthz")]
    pub path: String,
    /// Seconds to wait for the answer.
    #[arg(long, default_value_t = 3.0, value_parser = parse_finite)]
    pub timeout_s: f64,
}

/// `irs-planner healthcheck`.
pub fn run_healthcheck(args: &HealthcheckArgs) -> Result<(), Failure> {
    if !args.path.starts_with('/') {
        return Err(Failure::input(format!(
            "--path {:?}: must start with /",
            args.path
        )));
    }
    if !(args.timeout_s > 0.0 && args.timeout_s <= 600.0) {
        return Err(Failure::input(format!(
            "--timeout-s {}: must be in (0, 600]",
            args.timeout_s
        )));
    }
    let url = irs_service::probe::local_url(args.bind, &args.path);
    match irs_service::probe::probe(&url, std::time::Duration::from_secs_f64(args.timeout_s)) {
        Ok(status) if (200..300).contains(&status) => {
            println!("{url}: {status}");
            Ok(())
        }
        Ok(status) => Err(Failure::runtime(format!("{url}: {status}"))),
        Err(reason) => Err(Failure::runtime(reason)),
    }
}

#[derive(Debug, Args)]
pub struct PlaceArgs {
    #[command(flatten)]
    pub source: ScenarioSource,
    /// What moves: irs or ap.
    #[arg(long, default_value = "irs", value_parser = irs_model::input::parse_name::<What>)]
    pub what: What,
    /// Which IRS (or AP) of the scenario moves, in scenario order.
    #[arg(long, default_value_t = 0)]
    pub index: usize,
    /// A wall to sample candidates along, "x0,y0:x1,y1" (repeatable; needs --step).
    #[arg(long = "wall", value_name = "FROM:TO", allow_hyphen_values = true, value_parser = parse_wall)]
    pub walls: Vec<Segment>,
    /// Spacing (m) of the wall samples.
    #[arg(long, value_parser = parse_finite)]
    pub step: Option<f64>,
    /// Height (m) of the wall samples (default: the moving device's present height).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub height: Option<f64>,
    /// An explicit IRS pose "x,y,z:nx,ny,nz" (repeatable).
    #[arg(long = "pose", value_name = "CENTER:NORMAL", allow_hyphen_values = true, value_parser = parse_pose)]
    pub poses: Vec<Pose>,
    /// An explicit AP position "x,y,z" (repeatable).
    #[arg(long = "position", value_name = "X,Y,Z", allow_hyphen_values = true, value_parser = irs_model::input::parse_point3)]
    pub positions: Vec<[f64; 3]>,
    /// The objective: coverage (needs --threshold), max_threshold (needs --start, --goal) or
    /// distance (needs all three).
    #[arg(long)]
    pub objective: String,
    /// QoS threshold γ (dB) of the coverage and distance objectives.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub threshold: Option<f64>,
    /// Start point "X,Y" (m) of the path objectives.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub start: Option<[f64; 2]>,
    /// Goal point "X,Y" (m) of the path objectives.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub goal: Option<[f64; 2]>,
    /// IRS phases of the gain maps: continuous or a number of bits (default continuous).
    #[arg(long)]
    pub phases: Option<PhaseMode>,
    /// Draw the best candidate's map as a PNG into this file.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// No progress bar on stderr.
    #[arg(long)]
    pub quiet: bool,
}

fn parse_wall(text: &str) -> Result<Segment, String> {
    let (from, to) = text
        .split_once(':')
        .ok_or_else(|| format!("expected \"x0,y0:x1,y1\", got {text:?}"))?;
    Ok(Segment {
        from: parse_point(from)?,
        to: parse_point(to)?,
    })
}

fn parse_pose(text: &str) -> Result<Pose, String> {
    let (center, normal) = text
        .split_once(':')
        .ok_or_else(|| format!("expected \"x,y,z:nx,ny,nz\", got {text:?}"))?;
    Ok(Pose {
        center: irs_model::input::parse_point3(center)?,
        normal: irs_model::input::parse_point3(normal)?,
    })
}

/// Where the scenario comes from: a file, and optionally a floor plan that sets or replaces the
/// file's own.
#[derive(Debug, Args)]
pub struct ScenarioSource {
    /// Scenario JSON file.
    #[arg(long)]
    pub scenario: PathBuf,
    /// A ROS map YAML (Nav2 map_server format) that sets or replaces the scenario's floor plan.
    #[arg(long, value_name = "MAP_YAML")]
    pub floor_plan: Option<PathBuf>,
    /// Height (m) of the floor plan's occupied pixels (default: the ceiling).
    #[arg(long, value_name = "M", requires = "floor_plan", allow_hyphen_values = true, value_parser = parse_finite)]
    pub obstacle_height: Option<f64>,
}

#[derive(Debug, Args)]
pub struct ScenarioArgs {
    #[command(flatten)]
    pub source: ScenarioSource,
}

#[derive(Debug, Args)]
pub struct ExportArgs {
    #[command(flatten)]
    pub map: MapArgs,
    /// QoS threshold γ of the masks, in --unit (by default the map's: dB or bit/s/Hz).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub threshold: f64,
    /// The value that costs 0 in the cost mask, in --unit (default: the map's maximum).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub best: Option<f64>,
    /// The unit of the threshold, of `best` and of map.npy's values: gain_db, dbm, snr_db,
    /// bps_hz or mbps (docs/model.md §3.1); default: the map's own.
    #[arg(long, value_name = "UNIT")]
    pub unit: Option<Unit>,
    /// Folder to write keepout.{yaml,pgm}, cost.{yaml,pgm} and map.npy into (created if needed).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

#[derive(Debug, Args)]
pub struct MapArgs {
    #[command(flatten)]
    pub source: ScenarioSource,
    /// Map kind: gain (dB) or rate (bit/s/Hz).
    #[arg(long)]
    pub kind: MapKind,
    /// IRS phases: continuous, none, or a number of bits (1–16).
    #[arg(long)]
    pub phases: Option<PhaseMode>,
    /// Multiple access, noma or oma (rate maps; default noma).
    #[arg(long)]
    pub access: Option<Access>,
    /// Rate-map solver, fast or sdr-sca (default fast).
    #[arg(long)]
    pub solver: Option<SolverKind>,
    /// No progress bar on stderr.
    #[arg(long)]
    pub quiet: bool,
    /// Also draw the map (and, for `plan`, the path) as a PNG into this file.
    #[arg(long, value_name = "FILE")]
    pub png: Option<PathBuf>,
    /// Pixels per grid cell in the PNG (1–32; default: the longer side fits in 768 px).
    #[arg(long, value_name = "PX", requires = "png", value_parser = clap::value_parser!(u16).range(1..=render::MAX_CELL_PX as i64))]
    pub cell_px: Option<u16>,
}

#[derive(Debug, Args)]
pub struct PlanArgs {
    #[command(flatten)]
    pub map: MapArgs,
    /// Start point "X,Y" (m); snapped to the nearest cell centre.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub start: [f64; 2],
    /// Goal point "X,Y" (m); snapped to the nearest cell centre.
    #[arg(long, value_parser = parse_point, allow_hyphen_values = true)]
    pub goal: [f64; 2],
    /// QoS threshold in --unit (by default the map's: dB or bit/s/Hz), or "max".
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "max_threshold",
        required_unless_present = "max_threshold"
    )]
    pub threshold: Option<Threshold>,
    /// The unit of the threshold and of the values printed: gain_db, dbm, snr_db, bps_hz or
    /// mbps (docs/model.md §3.1); default: the map's own (gain_db or bps_hz).
    #[arg(long, value_name = "UNIT")]
    pub unit: Option<Unit>,
    /// The route's shape: grid (8-connected steps, the paper's), any_angle (straight segments
    /// wherever every cell crossed meets the threshold; never longer) or route_graph (along the
    /// scenario's route graph, between the nodes nearest start and goal).
    #[arg(long, value_name = "SHAPE", default_value = "grid")]
    pub path_shape: PathShape,
    /// How far (m) a start or goal in an obstacle or below the threshold may move to the
    /// nearest feasible cell (the answer says where; default 0: not at all).
    #[arg(
        long,
        value_name = "METRES",
        default_value = "0",
        allow_hyphen_values = true,
        value_parser = parse_finite
    )]
    pub tolerance: f64,
    /// Use the largest threshold for which a path exists (the same as --threshold max).
    #[arg(long)]
    pub max_threshold: bool,
    /// Check the path by Monte Carlo with this many Rician draws per waypoint (paper Fig. 10).
    #[arg(long, value_name = "DRAWS")]
    pub monte_carlo: Option<usize>,
    /// How finely the waypoints' phases are written in radians: 1e-2, 1e-3, 1e-4, 1e-6 or full
    /// (default 1e-4).
    #[arg(long, value_name = "STEP")]
    pub phase_precision: Option<PhasePrecision>,
    /// How the waypoints' phases are written: radians (irs_phases_rad) or codes (16-bit codes
    /// in base64, irs_phase_codes; θ = 2π·c/65536).
    #[arg(long, value_name = "FORMAT", default_value = "radians")]
    pub phase_format: PhaseFormat,
    /// The frame the answer names for its positions (a ROS tf2 frame id).
    #[arg(long, value_name = "FRAME", default_value = "map", value_parser = FrameId::parse)]
    pub frame_id: FrameId,
    /// What to print: json (the path answer), nav-msgs-path (a ROS 2 nav_msgs/Path message as
    /// JSON, which is also the YAML `ros2 topic pub` takes), csv (x,y,yaw_rad,time_s,
    /// distance_m,value per waypoint) or vda5050-order (a VDA 5050 3.0.0 order; its options
    /// below).
    #[arg(long, value_name = "FORMAT", default_value = "json")]
    pub output: RouteFormat,
    /// Seed of the Monte Carlo check.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub order: OrderArgs,
}

/// A CLI failure: the message and whether it was the user's input (exit 2) or not (exit 1).
pub struct Failure {
    pub message: String,
    pub kind: FailureKind,
}

/// Why a command failed, which its exit status tells a script.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailureKind {
    /// Something other than the input failed: exit 1.
    Runtime,
    /// The user's input was wrong: exit 2.
    Input,
    /// `plan` answered, but no path meets the threshold: exit 3 (the answer, with its
    /// `reason`, is printed as for a feasible path).
    NoPath,
}

impl FailureKind {
    fn exit_code(self) -> u8 {
        match self {
            FailureKind::Runtime => 1,
            FailureKind::Input => 2,
            FailureKind::NoPath => 3,
        }
    }
}

impl Failure {
    /// The user's input was wrong (exit 2).
    pub fn input(message: impl Into<String>) -> Self {
        Failure {
            message: message.into(),
            kind: FailureKind::Input,
        }
    }
    /// Something other than the input failed (exit 1).
    pub fn runtime(message: impl Into<String>) -> Self {
        Failure {
            message: message.into(),
            kind: FailureKind::Runtime,
        }
    }
}

/// A field error as the CLI names it: the request field's flag (`phase_precision` →
/// `--phase-precision`) and the reason.
fn flag(e: &FieldError) -> String {
    format!("--{}: {}", e.field.replace('_', "-"), e.reason)
}

impl From<Failure> for ExitCode {
    fn from(f: Failure) -> ExitCode {
        eprintln!("error: {}", f.message);
        ExitCode::from(f.kind.exit_code())
    }
}

/// Reads the scenario a command names: its file, with `--floor-plan` (read relative to the
/// working directory) setting or replacing the floor plan.
pub fn load_scenario(source: &ScenarioSource) -> Result<Scenario, Failure> {
    let path = &source.scenario;
    let fail =
        |e: &dyn std::fmt::Display| Failure::input(format!("--scenario {}: {e}", path.display()));
    let text =
        irs_answers::files::read_regular_text(path, irs_answers::files::MAX_SCENARIO_FILE_BYTES)
            .map_err(|e| fail(&e))?;
    let mut document = irs_answers::scenario::document(&text).map_err(|e| fail(&e))?;
    if let Some(map_yaml) = &source.floor_plan {
        let absolute = std::path::absolute(map_yaml)
            .map_err(|e| Failure::input(format!("--floor-plan {}: {e}", map_yaml.display())))?;
        let mut plan = serde_json::json!({ "map": absolute });
        if let Some(h) = source.obstacle_height {
            plan["obstacle_height_m"] = h.into();
        }
        match document.as_object_mut() {
            Some(object) => object.insert("floor_plan".into(), plan),
            None => return Err(fail(&"$: a scenario is a JSON object")),
        };
    }
    let base = path.parent().unwrap_or(Path::new("."));
    Scenario::from_value_with_files(document, base).map_err(|e| match &source.floor_plan {
        Some(map_yaml) if e.field.starts_with("floor_plan") => {
            Failure::input(format!("--floor-plan {}: {e}", map_yaml.display()))
        }
        _ => fail(&e),
    })
}

fn map_key(args: &MapArgs, scenario: &Scenario) -> Result<MapKey, Failure> {
    MapKey::new(
        &scenario.content_hash(),
        scenario,
        args.kind,
        args.phases,
        args.access,
        args.solver,
    )
    .map_err(|e| Failure::input(format!("--{}", e)))
}

fn build_map(args: &MapArgs, scenario: &Scenario) -> Result<RadioMap, Failure> {
    let key = map_key(args, scenario)?;
    let progress = Progress::default();
    let result = with_progress_bar(&progress, args.quiet, "map", "cells", || {
        irs_answers::map::build(scenario, &key, &progress)
    });
    result.map_err(|e| Failure::runtime(e.to_string()))
}

/// Runs `work` while a thread draws `progress` as a bar on stderr (unless `quiet`).
fn with_progress_bar<T>(
    progress: &Progress,
    quiet: bool,
    what: &str,
    unit: &str,
    work: impl FnOnce() -> T,
) -> T {
    // The bar redraws every 100 ms until `stop` is dropped, which wakes it at once: a sleep
    // there held every finished command up to 100 ms.
    let (stop, stopped) = std::sync::mpsc::channel::<()>();
    std::thread::scope(|scope| {
        let bar_thread = (!quiet).then(|| {
            let template =
                format!("{{spinner}} {what} {{bar:40}} {{pos}}/{{len}} {unit} ({{eta}})");
            scope.spawn(move || {
                let bar = indicatif::ProgressBar::new(0);
                bar.set_style(
                    indicatif::ProgressStyle::with_template(&template).expect("valid template"),
                );
                loop {
                    bar.set_length(progress.cells_total() as u64);
                    bar.set_position(progress.cells_done() as u64);
                    match stopped.recv_timeout(Duration::from_millis(100)) {
                        Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
                        _ => break,
                    }
                }
                bar.finish_and_clear();
            })
        });
        let result = work();
        drop(stop);
        if let Some(t) = bar_thread {
            let _ = t.join();
        }
        result
    })
}

/// Writes `value` as one line of JSON to standard output, serialised straight into a buffered
/// writer: a map body is tens of megabytes, which a string first would copy twice more.
fn print_json(value: &impl Serialize) -> Result<(), Failure> {
    use std::io::Write as _;
    let mut out = std::io::BufWriter::with_capacity(1 << 16, std::io::stdout().lock());
    let written = serde_json::to_writer(&mut out, value)
        .map_err(std::io::Error::from)
        .and_then(|()| out.write_all(b"\n"))
        .and_then(|()| out.flush());
    match written {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(Failure::runtime(format!("writing the answer: {e}")))
        }
        _ => Ok(()),
    }
}

/// Writes `text` to standard output. A reader that stopped reading (`| head`) is not an error:
/// what it wanted it has, as for any Unix filter; `print!` would panic there.
fn print_text(text: &[u8]) -> Result<(), Failure> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    match out.write_all(text).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(Failure::runtime(format!("writing the answer: {e}")))
        }
        _ => Ok(()),
    }
}

fn write_png(
    args: &MapArgs,
    map: &RadioMap,
    scenario: &Scenario,
    options: RenderOptions,
) -> Result<(), Failure> {
    let Some(file) = &args.png else { return Ok(()) };
    let options = RenderOptions {
        cell_px: args.cell_px.map(usize::from),
        ..options
    };
    let bytes = render::png(map, scenario, &options)
        .map_err(|e| Failure::input(flag(&e)))?
        .ok_or_else(|| {
            Failure::input(format!(
                "--cell-px: the picture would exceed {} pixels a side",
                render::MAX_SIDE_PX
            ))
        })?;
    std::fs::write(file, bytes)
        .map_err(|e| Failure::input(format!("--png {}: {e}", file.display())))
}

/// `irs-planner map …`
pub fn run_map(args: &MapArgs) -> Result<(), Failure> {
    let scenario = load_scenario(&args.source)?;
    let started = Instant::now();
    let map = build_map(args, &scenario)?;
    let body = Timed::since(started, irs_answers::map::body(&map));
    write_png(args, &map, &scenario, RenderOptions::default())?;
    print_json(&body)
}

/// `irs-planner estimate …`
pub fn run_estimate(args: &MapArgs) -> Result<(), Failure> {
    let scenario = load_scenario(&args.source)?;
    let key = map_key(args, &scenario)?;
    print_json(&serde_json::json!({
        "cpu_s": cost::build_seconds(&scenario, &key),
        "bytes": cost::map_bytes(&scenario, &key),
    }))
}

/// `irs-planner plan …`
pub fn run_plan(args: &PlanArgs) -> Result<(), Failure> {
    if let Some(draws) = args.monte_carlo
        && (draws == 0 || draws > MAX_DRAWS)
    {
        return Err(Failure::input(format!(
            "--monte-carlo: must lie in 1..={MAX_DRAWS}"
        )));
    }
    if args.monte_carlo.is_some() && args.output != RouteFormat::Json {
        return Err(Failure::input(
            "--monte-carlo: its report is part of the json output only",
        ));
    }
    let order = args.order.params();
    if order.is_some() && args.output != RouteFormat::Vda5050Order {
        return Err(Failure::input(
            "--order-id, --release-margin and the other order options apply to --output vda5050-order only",
        ));
    }
    let order = order.unwrap_or_default();
    order.validate().map_err(|e| Failure::input(vda_flag(&e)))?;
    if !(0.0..=planner::MAX_TOLERANCE_M).contains(&args.tolerance) {
        return Err(Failure::input(format!(
            "--tolerance: must lie in [0, {}] m",
            planner::MAX_TOLERANCE_M
        )));
    }
    let scenario = load_scenario(&args.map.source)?;
    let map = build_map(&args.map, &scenario)?;
    let threshold = args.threshold.unwrap_or(Threshold::Max);
    let started = Instant::now();
    let (format, precision) = path::phase_options(Some(args.phase_format), args.phase_precision)
        .map_err(|e| Failure::input(flag(&e)))?;
    let unit = args.unit.unwrap_or(map.native_unit());
    let path = match args.path_shape {
        PathShape::RouteGraph => map.values_in(unit).and_then(|values| {
            path::plan_on_route_graph(
                &scenario,
                &map,
                (unit, &values),
                args.tolerance,
                args.start,
                args.goal,
                threshold,
            )
        }),
        // The server's way: the widest-path threshold from the map's index, whose cost does
        // not depend on the direction of the query (the search's did, by 9–28×).
        shape => planner::UnitIndex::new(&map, unit).and_then(|index| {
            planner::plan_indexed(
                &map,
                &index,
                planner::PathOptions {
                    shape,
                    tolerance_m: args.tolerance,
                },
                args.start,
                args.goal,
                threshold,
                scenario.mru.v_max_mps,
            )
        }),
    }
    .map_err(|e| Failure::input(flag(&e)))?;
    let mut path = path::write_phases(&scenario, &map, path, format, precision);
    path.frame_id = args.frame_id.as_str().to_string();
    write_png(
        &args.map,
        &map,
        &scenario,
        RenderOptions::for_path(&map, &path),
    )?;
    let monte_carlo = match args.monte_carlo {
        Some(draws) if path.feasible => {
            let progress = Progress::default();
            let checked = with_progress_bar(
                &progress,
                args.map.quiet,
                "monte carlo",
                "waypoints",
                || path::check(&scenario, &map, &path, draws, args.seed, &progress),
            );
            // Nothing cancels a CLI check: the progress is ours alone.
            Some(checked.map_err(|e| Failure::runtime(e.to_string()))?)
        }
        _ => None,
    };
    let reason = (!path.feasible).then(|| {
        path.reason
            .and_then(|r| serde_json::to_value(r).ok())
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_else(|| "infeasible".into())
    });
    match args.output {
        RouteFormat::Json => {
            let took_ms = timing::took_ms(started);
            let mut body = CheckedPath { path, monte_carlo }.to_json();
            // Reopened for took_ms, last as in every timed answer.
            body.pop();
            timing::close_with_took_ms(&mut body, took_ms);
            body.push(b'\n');
            print_text(&body)?
        }
        RouteFormat::NavMsgsPath => print_json(&route::nav_msgs_path(&path))?,
        RouteFormat::Csv => print_text(route::csv(&path).as_bytes())?,
        // No route, no order: the exit status says so.
        RouteFormat::Vda5050Order if !path.feasible => {}
        RouteFormat::Vda5050Order => print_json(
            &vda5050::order(&path, &order, SystemTime::now())
                .map_err(|e| Failure::input(vda_flag(&e)))?,
        )?,
    }
    match reason {
        None => Ok(()),
        Some(reason) => Err(Failure {
            message: if args.output == RouteFormat::Vda5050Order {
                format!("no path meets the threshold ({reason}): no order written")
            } else {
                format!("no path meets the threshold ({reason}); the answer above says why")
            },
            kind: FailureKind::NoPath,
        }),
    }
}

/// `irs-planner export …`: the masks at `--threshold` and the values, written into `--out`;
/// prints the files written, as JSON.
pub fn run_export(args: &ExportArgs) -> Result<(), Failure> {
    let scenario = load_scenario(&args.map.source)?;
    let map = build_map(&args.map, &scenario)?;
    let unit = args.unit.unwrap_or(map.native_unit());
    let keepout = export::nav2_mask(&map, unit, MaskKind::Keepout, args.threshold, None)
        .map_err(|e| Failure::input(flag(&e)))?;
    let cost = export::nav2_mask(&map, unit, MaskKind::Cost, args.threshold, args.best)
        .map_err(|e| Failure::input(flag(&e)))?;
    let values = export::npy(&map, unit).map_err(|e| Failure::input(flag(&e)))?;
    let out = &args.out;
    std::fs::create_dir_all(out)
        .map_err(|e| Failure::runtime(format!("--out {}: {e}", out.display())))?;
    let mut written = Vec::new();
    let files = [
        (keepout.yaml_name(), keepout.files.yaml.as_bytes()),
        (keepout.pgm_name(), keepout.files.pgm.as_slice()),
        (cost.yaml_name(), cost.files.yaml.as_bytes()),
        (cost.pgm_name(), cost.files.pgm.as_slice()),
        ("map.npy".to_string(), &values),
    ];
    for (name, bytes) in files {
        let path = out.join(&name);
        std::fs::write(&path, bytes)
            .map_err(|e| Failure::runtime(format!("--out {}: {e}", path.display())))?;
        written.push(path.display().to_string());
    }
    print_json(&serde_json::json!({
        "map_id": map.id,
        "threshold": args.threshold,
        "files": written,
    }))
}

/// `irs-planner scenario …`: the scenario as the API takes it.
pub fn run_scenario(args: &ScenarioArgs) -> Result<(), Failure> {
    print_json(&Document::from(&load_scenario(&args.source)?))
}

/// `irs-planner place …`
pub fn run_place(args: &PlaceArgs) -> Result<(), Failure> {
    let scenario = load_scenario(&args.source)?;
    let objective = match (
        args.objective.as_str(),
        args.threshold,
        args.start,
        args.goal,
    ) {
        ("coverage", Some(threshold), None, None) => Objective::Coverage { threshold },
        ("max_threshold", None, Some(start), Some(goal)) => Objective::MaxThreshold { start, goal },
        ("distance", Some(threshold), Some(start), Some(goal)) => Objective::Distance {
            threshold,
            start,
            goal,
        },
        (name @ ("coverage" | "max_threshold" | "distance"), ..) => {
            return Err(Failure::input(format!(
                "--objective {name}: coverage takes --threshold; max_threshold --start and \
                 --goal; distance all three"
            )));
        }
        (other, ..) => {
            return Err(Failure::input(format!(
                "--objective: expected coverage, max_threshold or distance, got {other:?}"
            )));
        }
    };
    let search = Search {
        what: args.what,
        index: args.index,
        candidates: Candidates {
            poses: args.poses.clone(),
            positions: args.positions.clone(),
            walls: args.walls.clone(),
            step_m: args.step,
            height_m: args.height,
        },
        objective,
        phases: args.phases,
    };
    let started = Instant::now();
    let progress = Progress::default();
    let placement = with_progress_bar(&progress, args.quiet, "placement", "cells", || {
        placement::place(&scenario, &search, &irs_answers::map::ContentIds, &progress)
    })
    .map_err(|e| match e {
        WorkError::Invalid(e) => Failure::input(flag(&e)),
        WorkError::Cancelled(e) => Failure::runtime(e.to_string()),
    })?;
    if let (Some(file), Some(best)) = (&args.png, placement.scenarios.first()) {
        let key = MapKey::gain(&best.content_hash(), best, placement.answer.phases)
            .map_err(|e| Failure::input(flag(&e)))?;
        let map = irs_answers::map::build(best, &key, &Progress::default())
            .map_err(|e| Failure::runtime(e.to_string()))?;
        let options = match placement.answer.objective {
            Objective::MaxThreshold { start, goal } | Objective::Distance { start, goal, .. } => {
                let threshold = match placement.answer.objective {
                    Objective::Distance { threshold, .. } => Threshold::Value(threshold),
                    _ => Threshold::Max,
                };
                let path = planner::plan(
                    &map,
                    map.native_unit(),
                    Default::default(),
                    start,
                    goal,
                    threshold,
                    best.mru.v_max_mps,
                )
                .map_err(|e| Failure::input(flag(&e)))?;
                RenderOptions::for_path(&map, &path)
            }
            Objective::Coverage { threshold } => RenderOptions {
                threshold: Some(threshold),
                ..RenderOptions::default()
            },
        };
        let bytes = render::png(&map, best, &options)
            .map_err(|e| Failure::runtime(e.to_string()))?
            .ok_or_else(|| Failure::runtime("the picture would be too large"))?;
        std::fs::write(file, bytes)
            .map_err(|e| Failure::input(format!("--png {}: {e}", file.display())))?;
    }
    print_json(&Timed::since(started, placement.answer))
}
