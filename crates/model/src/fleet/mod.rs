//! Several robots at once (docs/model.md §6.5): robots that share APs and IRSs, planned one after
//! another in priority order so that every robot's requirement holds at every time step.
//!
//! * [`joint`]: one instant, what every IRS holds and what every robot gets.
//! * [`search`]: one robot's route in space and time, given the routes already fixed.
//!
//! Time runs in steps of Δt. A move to an orthogonal neighbour takes ⌈Δ/(V_max·Δt)⌉ steps, a
//! diagonal one ⌈√2·Δ/(V_max·Δt)⌉ (1 and 2 at the default Δt = Δ/V_max), so no robot exceeds
//! V_max; a robot may also wait a step in place. During a move of several steps a robot is
//! measured at the cell it leaves and holds both cells. Once arrived it stays at its goal,
//! still connected, until the plan ends. Two robots never hold one cell at one step nor swap
//! cells between consecutive steps; collisions beyond that (robot bodies, speeds) are the
//! fleet manager's. Robots not yet planned wait at their starts, which the robots planned
//! before them avoid.

mod joint;
mod search;
mod sharing;

pub use joint::Configuration;

use crate::input::FieldError;
use crate::planner::{CellGraph, DEFAULT_FRAME, Endpoint, Infeasible};
use crate::radiomap::{Cancelled, CellSolutions, Progress, RadioMap, Unit, WorkError};
use crate::rate::Access;
use crate::scenario::{Grid, Sru};
use joint::{JointChannel, Link};
use search::{Track, World};
use serde::Serialize;

/// At most this many robots in one plan.
pub const MAX_ROBOTS: usize = 32;
/// At most this many time steps in a plan's horizon.
pub const MAX_STEPS: usize = 20_000;
/// At most this many steps a move between neighbouring cells (Δt at least Δ/(V_max·64)).
pub const MAX_MOVE_STEPS: usize = 64;
/// At most this many space–time states expanded for one robot: the search's bound on work and
/// memory (≈ 100 bytes a state, 50 MB at most), reported as [`Unserved::Budget`] when reached.
pub const MAX_EXPANSIONS: usize = 500_000;
/// At most this many states expanded for a whole plan (a few seconds of one core on the largest
/// floors): the robots planned once it is spent are reported [`Unserved::Budget`].
pub const MAX_PLAN_EXPANSIONS: usize = 2_000_000;
/// A requirement is met when the gain is at least 1 − 10⁻⁹ of the required one: the rounding
/// of a phasor sum, so a cell exactly at the threshold on the map is met in the plan too.
const MET_TOLERANCE: f64 = 1e-9;

/// At most this many poses in a given route.
pub const MAX_ROUTE_POSES: usize = 10_000;

/// One robot of a fleet request. Robots with a given route come first (they drive as given);
/// the others are planned after them in request order.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotRequest {
    /// How it moves.
    pub motion: Motion,
    /// Its requirement at every step, in the request's unit, through its serving AP.
    pub threshold: f64,
}

/// How a robot of a fleet request moves.
#[derive(Debug, Clone, PartialEq)]
pub enum Motion {
    /// From `start` to `goal` (x, y) (m), each snapped to the nearest cell centre: planned.
    Trip {
        /// Where it starts.
        start: [f64; 2],
        /// Where it goes.
        goal: [f64; 2],
    },
    /// Poses (x, y, t) (m, m, s), t strictly increasing from t ≥ 0: driven as given (a straight
    /// line at constant speed between poses, at the first pose before its time, at the last
    /// after it) and checked, not planned; e.g. a path answer's waypoints with their times.
    Route(Vec<[f64; 3]>),
}

impl Motion {
    /// The first and last point.
    fn ends(&self) -> ([f64; 2], [f64; 2]) {
        match self {
            Motion::Trip { start, goal } => (*start, *goal),
            Motion::Route(poses) => {
                let (a, b) = (poses[0], poses[poses.len() - 1]);
                ([a[0], a[1]], [b[0], b[1]])
            }
        }
    }
}

/// How a fleet is planned.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FleetOptions {
    /// The unit of the robots' thresholds and of the values reported.
    pub unit: Unit,
    /// V_max (m/s), every robot's top speed.
    pub v_max_mps: f64,
    /// Δt (s); `None` for Δ/V_max, one cell a step.
    pub dt_s: Option<f64>,
    /// The latest arrival (s); `None` for twice the longest robot's route alone plus 64 steps.
    pub horizon_s: Option<f64>,
    /// How robots served by one AP share it: `None`, each has it to itself (requirements on
    /// its link in any unit); NOMA or OMA, they share its power (requirements are rates:
    /// `bps_hz` or `mbps`).
    pub access: Option<Access>,
}

/// A planned fleet.
#[derive(Debug, Clone, Serialize)]
pub struct FleetPlan {
    /// The unit of thresholds and values.
    pub unit: Unit,
    /// How robots of one AP share it (absent: each has it to itself).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub access: Option<Access>,
    /// Δt (s).
    pub dt_s: f64,
    /// Steps of an orthogonal and of a diagonal move.
    pub move_steps: [usize; 2],
    /// The latest arrival step the search allowed.
    pub horizon_steps: usize,
    /// The frame positions are in.
    pub frame: &'static str,
    /// Per robot, in request order.
    pub robots: Vec<RobotPlan>,
    /// Every step from 0 to the last arrival: what the IRSs held and what each robot got.
    pub timeline: Vec<Instant>,
    /// Every (robot, step) whose requirement is not met: empty for a plan this module made.
    pub violations: Vec<Violation>,
    /// Every pair of given routes that share a cell at a step or swap cells between two:
    /// planned robots never do, but routes given as poses are checked, not moved.
    pub conflicts: Vec<Conflict>,
}

/// Two given routes that meet: they share a cell at a step, or swap cells between two.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Conflict {
    /// The two robots (request order, the earlier first).
    pub robots: [usize; 2],
    /// The first step at which they meet.
    pub step: usize,
    /// Its time (s).
    pub time_s: f64,
    /// x of the cell where they first meet (m): the shared one, or the first robot's next.
    pub x: f64,
    /// y of that cell (m).
    pub y: f64,
    /// How many steps they meet at in all.
    pub steps: usize,
}

/// One robot's part of a plan.
#[derive(Debug, Clone, Serialize)]
pub struct RobotPlan {
    /// Where its start landed on the grid.
    pub start: Endpoint,
    /// Where its goal landed on the grid.
    pub goal: Endpoint,
    /// Its requirement, in the plan's unit.
    pub threshold: f64,
    /// How its route was found; absent when it could not be served.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub planned_by: Option<PlannedBy>,
    /// Why it could not be served; absent when it was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unserved: Option<Unserved>,
    /// The step it reaches its goal.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub arrival_step: Option<usize>,
    /// Steps spent waiting in place.
    pub waited_steps: usize,
    /// The route's length (m).
    pub distance_m: f64,
    /// Flat cell index per step from 0 to its arrival (the cell it is measured at).
    #[serde(skip)]
    pub cells: Vec<usize>,
}

/// How a robot's route was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PlannedBy {
    /// Its shortest route alone (the single-robot path), driven without waiting, held with
    /// every robot before it.
    Alone,
    /// The space–time search: the earliest arrival given the robots before it.
    SpaceTime,
    /// Its route was given: driven as given, checked, not planned.
    Given,
}

/// Why a robot could not be served.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(tag = "reason", rename_all = "snake_case")]
pub enum Unserved {
    /// Not even alone: no path of its own at its threshold.
    Alone {
        /// Why its own path fails.
        why: Infeasible,
    },
    /// At its start at step 0 it shares a cell with, or breaks the requirement of, a robot
    /// planned before it.
    StartConflict,
    /// No route reaches its goal by the horizon given the robots planned before it.
    Horizon {
        /// The horizon searched.
        horizon_steps: usize,
    },
    /// The search expanded [`MAX_EXPANSIONS`] states (or what was left of the plan's
    /// [`MAX_PLAN_EXPANSIONS`]) without an answer.
    Budget {
        /// States expanded.
        expanded: usize,
    },
}

/// One step of a plan.
#[derive(Debug, Clone, Serialize)]
pub struct Instant {
    /// k, from 0.
    pub step: usize,
    /// k·Δt (s).
    pub time_s: f64,
    /// Per surface, whom it served (a robot or an SRU), or `None`.
    pub served: Vec<Option<Party>>,
    /// θ per surface (rad, in [0, 2π)): the one configuration every robot sees.
    pub phases: Vec<Vec<f64>>,
    /// Per robot (request order), where it is and what it gets; `None` for a robot not served.
    pub robots: Vec<Option<RobotInstant>>,
    /// With `access`, per SRU of the scenario (its order), what it gets where it stands (x and
    /// y are its position, i and j its cell).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub srus: Vec<RobotInstant>,
}

/// Who takes part in a fleet instant: a robot of the request or an SRU of the scenario.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Party {
    /// A robot, by its request index.
    Robot(usize),
    /// A static robot of the scenario, by its index in `srus`.
    Sru(usize),
}

/// Where one robot is at one step and what it gets.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RobotInstant {
    /// x of its cell's centre (m).
    pub x: f64,
    /// y of its cell's centre (m).
    pub y: f64,
    /// Its cell's index along x.
    pub i: usize,
    /// Its cell's index along y.
    pub j: usize,
    /// The serving AP.
    pub ap: usize,
    /// Its link in the plan's unit, through its AP with all of the AP's power (with `access`
    /// the power is shared: a robot whose AP serves its group gets exactly its rate, with
    /// `power_share` of the power).
    pub value: f64,
    /// Whether it meets its requirement.
    pub met: bool,
    /// With `access`, where its AP serves its robots: its share of the AP's transmit power.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub power_share: Option<f64>,
    /// With NOMA, where its AP serves its robots: its place in the SIC order among them
    /// (0 = decoded first, the weakest).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decoded: Option<usize>,
}

/// A requirement not met.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Violation {
    /// Whose requirement: `{"robot": r}` or `{"sru": k}`.
    #[serde(flatten)]
    pub party: Party,
    /// The step.
    pub step: usize,
    /// Its time (s).
    pub time_s: f64,
    /// x of the robot's cell (m).
    pub x: f64,
    /// y of the robot's cell (m).
    pub y: f64,
    /// What it got, in the plan's unit.
    pub value: f64,
    /// What it needed.
    pub required: f64,
}

/// The robots' requirements as gains, and the channel at every cell, lazily.
pub(crate) struct Requirements<'m> {
    map: &'m RadioMap,
    joint: JointChannel,
    /// Per robot, the required gain (linear) through each AP: alone with all of its power.
    need: Vec<Vec<f64>>,
    /// With `access`, how robots of one AP share it.
    sharing: Option<Sharing>,
    /// Per cell, an index into `store` once computed.
    links: Vec<u32>,
    store: Vec<Link>,
}

const NO_LINK: u32 = u32::MAX;

impl<'m> Requirements<'m> {
    fn link(&mut self, cell: usize) -> usize {
        if self.links[cell] == NO_LINK {
            let (i, j) = self.map.grid.cell_of(cell);
            let link = self
                .joint
                .link(self.map.serving_ap(cell), self.map.grid.centre(i, j));
            self.links[cell] = self.store.len() as u32;
            self.store.push(link);
        }
        self.links[cell] as usize
    }

    /// The configuration at one step for `robots` at `cells`, and what each gets.
    fn instant(&mut self, robots: &[usize], cells: &[usize]) -> Evaluated {
        let ids: Vec<usize> = cells.iter().map(|&c| self.link(c)).collect();
        let statics: &[Static] = self.sharing.as_ref().map_or(&[], |s| &s.statics);
        let mut links: Vec<&Link> = ids.iter().map(|&k| &self.store[k]).collect();
        let mut need: Vec<f64> = robots
            .iter()
            .zip(&links)
            .map(|(&r, l)| self.need[r][l.ap])
            .collect();
        links.extend(statics.iter().map(|s| &s.link));
        need.extend(statics.iter().map(|s| s.need));
        let parties = links.len();
        let config = self.joint.configure(&links, &need);
        let Some(sharing) = &self.sharing else {
            let met = config
                .gains
                .iter()
                .zip(&need)
                .map(|(g, n)| *g >= n * (1.0 - MET_TOLERANCE))
                .collect();
            return Evaluated {
                config,
                met,
                shares: vec![None; parties],
            };
        };
        let mut met = vec![false; parties];
        let mut shares = vec![None; parties];
        let aps: Vec<usize> = links.iter().map(|l| l.ap).collect();
        for ap in 0..sharing.rho.len() {
            let group: Vec<usize> = (0..parties).filter(|&k| aps[k] == ap).collect();
            if group.is_empty() {
                continue;
            }
            let gains: Vec<f64> = group.iter().map(|&k| config.gains[k]).collect();
            let rates: Vec<f64> = group
                .iter()
                .map(|&k| match robots.get(k) {
                    Some(&r) => sharing.rates[r][ap],
                    None => statics[k - robots.len()].rate,
                })
                .collect();
            if let Some(share) = sharing::share(sharing.access, sharing.rho[ap], &gains, &rates) {
                for (g, &k) in group.iter().enumerate() {
                    met[k] = true;
                    let place = share.order.iter().position(|&o| o == g);
                    shares[k] = Some((share.fractions[g], place));
                }
            }
        }
        Evaluated {
            config,
            met,
            shares,
        }
    }
}

/// One step evaluated, per party: the robots asked for, then (with `access`) the scenario's
/// SRUs.
pub(crate) struct Evaluated {
    /// What the IRSs hold and each party's gain.
    pub config: Configuration,
    /// Per party, whether its requirement is met.
    pub met: Vec<bool>,
    /// With `access`, per party whose AP serves its group: its share of the AP's power and,
    /// with NOMA, its place in the SIC order.
    pub shares: Vec<Option<(f64, Option<usize>)>>,
}

/// A static robot of the scenario (an SRU, paper Section II-B): always there, needing its rate.
struct Static {
    link: Link,
    /// Its antenna (x, y, z) (m).
    position: [f64; 3],
    /// r̄_s (bit/s/Hz).
    rate: f64,
    /// The gain its rate needs alone with all of its AP's power (linear), for the policy.
    need: f64,
    /// Its cell, which no robot enters.
    cell: usize,
}

/// How robots of one AP share it, and what they need.
struct Sharing {
    access: Access,
    /// Per AP, ρ = P_max·G/σ²: the SNR of a unit gain with all of its power (§3.1).
    rho: Vec<f64>,
    /// Per robot, its rate (bit/s/Hz) through each AP.
    rates: Vec<Vec<f64>>,
    /// The scenario's SRUs.
    statics: Vec<Static>,
}

/// Plans `robots` on a gain map, in order (docs/model.md §6.5); with `access`, the scenario's
/// static robots `srus` take part, each needing its rate where it stands. Errors name the
/// request's field: `robots` (too many, an end off the floor), `unit`, `dt_s`, `horizon_s`,
/// `map`.
/// `progress` counts robots planned; cancelling it stops the search within a few thousand
/// states.
pub fn plan_fleet(
    map: &RadioMap,
    srus: &[Sru],
    robots: &[RobotRequest],
    options: FleetOptions,
    progress: &Progress,
) -> Result<FleetPlan, WorkError> {
    checked(map, srus, robots, options, |problem| problem.plan(progress))?
}

/// Every check [`plan_fleet`] makes before its search, and nothing after: what a service runs
/// before it admits a plan as a job, so a bad field is a 422 at once, not a failed job. It
/// costs each robot's route alone (one shortest-path search each).
pub fn check_fleet(
    map: &RadioMap,
    srus: &[Sru],
    robots: &[RobotRequest],
    options: FleetOptions,
) -> Result<(), FieldError> {
    checked(map, srus, robots, options, |_| ())
}

/// A fleet problem checked and ready to search: borrowing what [`checked`] derived.
struct Problem<'m> {
    robots: &'m [RobotRequest],
    options: FleetOptions,
    grid: &'m Grid,
    dt_s: f64,
    move_steps: [usize; 2],
    horizon_steps: usize,
    given: Vec<Option<Track>>,
    ends: Vec<((usize, Endpoint), (usize, Endpoint))>,
    alone: Vec<Result<Track, Infeasible>>,
    graph: CellGraph<'m>,
    req: Requirements<'m>,
}

/// Checks the request (each error names its field) and derives what the search needs, then
/// hands it to `then`. The problem borrows values derived here (the map's values in the
/// request's unit), hence a continuation rather than a returned struct.
fn checked<R>(
    map: &RadioMap,
    srus: &[Sru],
    robots: &[RobotRequest],
    options: FleetOptions,
    then: impl FnOnce(Problem<'_>) -> R,
) -> Result<R, FieldError> {
    let CellSolutions::Gain {
        models,
        antenna_height_m,
        ..
    } = &map.cells
    else {
        return Err(FieldError::new(
            "map",
            "fleet plans run on gain maps (robots sharing an AP, and the scenario's SRUs, are \
             given `access`)",
        ));
    };
    if robots.is_empty() || robots.len() > MAX_ROBOTS {
        return Err(FieldError::new(
            "robots",
            format!("expected 1 to {MAX_ROBOTS} robots, got {}", robots.len()),
        ));
    }
    let values = map.values_in(options.unit)?;
    let grid = &map.grid;
    let dt_s = options
        .dt_s
        .unwrap_or(grid.resolution_m / options.v_max_mps);
    if !(dt_s.is_finite() && dt_s > 0.0) {
        return Err(FieldError::new(
            "dt_s",
            format!("must be a positive number of seconds, got {dt_s}"),
        ));
    }
    let steps_of = |length_m: f64| {
        ((length_m / (options.v_max_mps * dt_s)) - 1e-9)
            .ceil()
            .max(1.0) as usize
    };
    if steps_of(std::f64::consts::SQRT_2 * grid.resolution_m) > MAX_MOVE_STEPS {
        return Err(FieldError::new(
            "dt_s",
            format!(
                "{dt_s} s is too short: a diagonal move of {:.3} m at {} m/s would take more \
                 than {MAX_MOVE_STEPS} steps",
                std::f64::consts::SQRT_2 * grid.resolution_m,
                options.v_max_mps
            ),
        ));
    }
    let move_steps = [
        steps_of(grid.resolution_m),
        steps_of(std::f64::consts::SQRT_2 * grid.resolution_m),
    ];
    // Given routes as tracks, checked before any work.
    let given: Vec<Option<Track>> = robots
        .iter()
        .enumerate()
        .map(|(r, robot)| match &robot.motion {
            Motion::Route(poses) => {
                given_track(grid, poses, dt_s, &format!("robots[{r}].route")).map(Some)
            }
            Motion::Trip { .. } => Ok(None),
        })
        .collect::<Result<_, FieldError>>()?;
    let ends = robots
        .iter()
        .enumerate()
        .map(|(r, robot)| {
            let (start, goal) = robot.motion.ends();
            let (start_field, goal_field) = match robot.motion {
                Motion::Trip { .. } => (format!("robots[{r}].start"), format!("robots[{r}].goal")),
                Motion::Route(_) => (format!("robots[{r}].route"), format!("robots[{r}].route")),
            };
            Ok((
                crate::planner::endpoint(grid, &start_field, start)?,
                crate::planner::endpoint(grid, &goal_field, goal)?,
            ))
        })
        .collect::<Result<Vec<_>, FieldError>>()?;
    let graph = crate::planner::graph(map, &values);
    // One jump point index for every robot's search on this map (its blocks worked out once).
    let jumps = crate::planner::JumpIndex::new(&graph);
    // Each robot's route on its own: a given route as given, a trip's shortest path alone (the
    // planner's first try); the longest sets the default horizon.
    let alone: Vec<Result<Track, Infeasible>> = robots
        .iter()
        .zip(&ends)
        .zip(&given)
        .map(|((robot, ((s, _), (g, _))), given)| match given {
            Some(track) => Ok(track.clone()),
            None => jumps
                .shortest_path(&graph, *s, *g, robot.threshold)
                .map(|p| search::timed(grid, &p.cells, move_steps)),
        })
        .collect();
    let horizon_steps = match options.horizon_s {
        Some(h) => {
            if !(h.is_finite() && h > 0.0) {
                return Err(FieldError::new(
                    "horizon_s",
                    format!("must be a positive number of seconds, got {h}"),
                ));
            }
            (h / dt_s).floor() as usize
        }
        None => {
            let longest = alone
                .iter()
                .filter_map(|a| a.as_ref().ok())
                .map(|t| t.at.len())
                .max()
                .unwrap_or(0);
            2 * longest + 64
        }
    };
    if horizon_steps > MAX_STEPS {
        return Err(FieldError::new(
            if options.horizon_s.is_some() {
                "horizon_s"
            } else {
                "dt_s"
            },
            format!(
                "the horizon is {horizon_steps} steps of {dt_s} s, more than {MAX_STEPS}: \
                 shorten horizon_s or lengthen dt_s"
            ),
        ));
    }
    let links = &map.links;
    let need: Vec<Vec<f64>> = robots
        .iter()
        .map(|robot| {
            links
                .iter()
                .map(|l| 10f64.powf(l.gain_db_for(options.unit, robot.threshold) / 10.0))
                .collect()
        })
        .collect();
    let joint = JointChannel::new(models.clone(), *antenna_height_m, map.key.phases);
    let sharing = match options.access {
        None => None,
        Some(access) => {
            if !matches!(options.unit, Unit::BpsHz | Unit::Mbps) {
                return Err(FieldError::new(
                    "unit",
                    format!(
                        "with access {access}, requirements are rates: bps_hz or mbps, got {}",
                        options.unit.name()
                    ),
                ));
            }
            Some(Sharing {
                access,
                rho: links
                    .iter()
                    .map(|l| 10f64.powf((l.offset_dbm - l.noise_dbm) / 10.0))
                    .collect(),
                rates: robots
                    .iter()
                    .map(|robot| {
                        links
                            .iter()
                            .map(|l| match options.unit {
                                Unit::Mbps => {
                                    robot.threshold / l.bandwidth_mhz.expect("checked by values_in")
                                }
                                _ => robot.threshold,
                            })
                            .collect()
                    })
                    .collect(),
                statics: srus
                    .iter()
                    .enumerate()
                    .map(|(k, sru)| {
                        let [x, y, _] = sru.position;
                        let (i, j) = grid.snap(x, y).ok_or_else(|| {
                            FieldError::new(format!("srus[{k}].position"), "lies outside the room")
                        })?;
                        let cell = grid.index(i, j);
                        let ap = map.serving_ap(cell);
                        let rate = sru.min_rate_bps_hz;
                        Ok(Static {
                            link: joint.link_at(ap, sru.position),
                            position: sru.position,
                            rate,
                            need: 10f64.powf(links[ap].gain_db_for(Unit::BpsHz, rate) / 10.0),
                            cell,
                        })
                    })
                    .collect::<Result<_, FieldError>>()?,
            })
        }
    };
    let req = Requirements {
        map,
        joint,
        need,
        sharing,
        links: vec![NO_LINK; grid.cells()],
        store: Vec::new(),
    };
    Ok(then(Problem {
        robots,
        options,
        grid,
        dt_s,
        move_steps,
        horizon_steps,
        given,
        ends,
        alone,
        graph,
        req,
    }))
}

impl Problem<'_> {
    /// Plans the robots in order (given routes first) and writes the timeline.
    fn plan(self, progress: &Progress) -> Result<FleetPlan, WorkError> {
        let Problem {
            robots,
            options,
            grid,
            dt_s,
            move_steps,
            horizon_steps,
            given,
            ends,
            alone,
            graph,
            mut req,
        } = self;
        let occupied_by_srus: Vec<u32> = req.sharing.as_ref().map_or(Vec::new(), |s| {
            s.statics.iter().map(|s| s.cell as u32).collect()
        });
        let mut world = World::new(graph, move_steps, horizon_steps, progress, occupied_by_srus);
        progress.start(robots.len());
        // Given routes are fixed first, then the trips are planned in request order.
        let order: Vec<usize> = (0..robots.len())
            .filter(|&r| given[r].is_some())
            .chain((0..robots.len()).filter(|&r| given[r].is_none()))
            .collect();
        let mut plans: Vec<Option<RobotPlan>> = vec![None; robots.len()];
        for (position, &r) in order.iter().enumerate() {
            if progress.is_cancelled() {
                return Err(Cancelled.into());
            }
            let robot = &robots[r];
            let ((start, start_end), (goal, goal_end)) = ends[r].clone();
            let outcome = if let Some(track) = &given[r] {
                Ok((track.clone(), PlannedBy::Given))
            } else {
                // The trips after this one wait at their starts meanwhile.
                let parked: Vec<usize> =
                    order[position + 1..].iter().map(|&q| ends[q].0.0).collect();
                match &alone[r] {
                    Err(why) => Err(Unserved::Alone { why: *why }),
                    Ok(route) => {
                        world.plan(&mut req, r, robot.threshold, route, start, goal, &parked)?
                    }
                }
            };
            progress.advance(1);
            let mut plan = RobotPlan {
                start: start_end,
                goal: goal_end,
                threshold: robot.threshold,
                planned_by: None,
                unserved: None,
                arrival_step: None,
                waited_steps: 0,
                distance_m: 0.0,
                cells: Vec::new(),
            };
            match outcome {
                Ok((track, by)) => {
                    plan.planned_by = Some(by);
                    plan.arrival_step = Some(track.at.len() - 1);
                    (plan.waited_steps, plan.distance_m) = match &robot.motion {
                        Motion::Route(poses) => (0, polyline_length(poses)),
                        Motion::Trip { .. } => (
                            track.waited(),
                            track.distance_cells(grid) * grid.resolution_m,
                        ),
                    };
                    plan.cells = track.at.iter().map(|&c| c as usize).collect();
                    world.fix(r, track);
                }
                Err(why) => plan.unserved = Some(why),
            }
            plans[r] = Some(plan);
        }
        let plans: Vec<RobotPlan> = plans.into_iter().map(|p| p.expect("every robot")).collect();
        let (timeline, violations) = world.timeline(&mut req, &plans, options.unit, dt_s);
        let tracks: Vec<(usize, &Track)> = given
            .iter()
            .enumerate()
            .filter_map(|(r, t)| Some((r, t.as_ref()?)))
            .collect();
        let conflicts = search::meetings(&tracks)
            .into_iter()
            .map(|m| {
                let (i, j) = grid.cell_of(m.cell as usize);
                let [x, y] = grid.centre(i, j);
                Conflict {
                    robots: m.robots,
                    step: m.step,
                    time_s: m.step as f64 * dt_s,
                    x,
                    y,
                    steps: m.steps,
                }
            })
            .collect();
        Ok(FleetPlan {
            unit: options.unit,
            access: options.access,
            dt_s,
            move_steps,
            horizon_steps,
            frame: DEFAULT_FRAME,
            robots: plans,
            timeline,
            violations,
            conflicts,
        })
    }
}

/// A given route's track: at step k the cell of its position at time k·Δt. Errors name the
/// pose (`robots[2].route[5]`): off the floor, a time not after the one before, too many poses
/// or too long a route.
fn given_track(
    grid: &Grid,
    poses: &[[f64; 3]],
    dt_s: f64,
    field: &str,
) -> Result<Track, FieldError> {
    if poses.is_empty() || poses.len() > MAX_ROUTE_POSES {
        return Err(FieldError::new(
            field,
            format!("expected 1 to {MAX_ROUTE_POSES} poses, got {}", poses.len()),
        ));
    }
    for (k, p) in poses.iter().enumerate() {
        let here = format!("{field}[{k}]");
        if !p.iter().all(|v| v.is_finite()) {
            return Err(FieldError::new(here, "x, y and t must be finite"));
        }
        if grid.snap(p[0], p[1]).is_none() {
            return Err(FieldError::new(
                here,
                format!("({}, {}) lies outside the room", p[0], p[1]),
            ));
        }
        let after = if k == 0 {
            p[2] >= 0.0
        } else {
            p[2] > poses[k - 1][2]
        };
        if !after {
            return Err(FieldError::new(
                here,
                "t must be at least 0 and increase strictly from pose to pose",
            ));
        }
    }
    let last_t = poses[poses.len() - 1][2];
    let steps = (last_t / dt_s).ceil();
    if steps > MAX_STEPS as f64 {
        return Err(FieldError::new(
            field,
            format!("it ends at {last_t} s, {steps} steps of {dt_s} s: more than {MAX_STEPS}"),
        ));
    }
    let mut at = Vec::with_capacity(steps as usize + 1);
    let mut segment = 0;
    for k in 0..=steps as usize {
        let t = k as f64 * dt_s;
        while segment + 1 < poses.len() && poses[segment + 1][2] <= t {
            segment += 1;
        }
        let p = poses[segment];
        let [x, y] = match poses.get(segment + 1) {
            Some(q) if t > p[2] => {
                let f = (t - p[2]) / (q[2] - p[2]);
                [p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])]
            }
            _ => [p[0], p[1]],
        };
        let (i, j) = grid.snap(x, y).expect("between two points of the room");
        at.push(grid.index(i, j) as u32);
    }
    Ok(Track::still(at))
}

/// The length of a route's polyline (m).
fn polyline_length(poses: &[[f64; 3]]) -> f64 {
    poses
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum()
}

#[cfg(test)]
mod tests;
