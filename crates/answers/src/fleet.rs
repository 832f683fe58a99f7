//! Fleet plans (docs/model.md §6.5, docs/api.md "Fleet plans"): the request `POST
//! /v1/fleet-plans` and `irs-planner fleet` share, checked field by field, and the answer both
//! write: per robot its timed waypoints, per step what every IRS held and what every robot got.

use irs_model::fleet::{self, FleetOptions, FleetPlan, Motion, RobotRequest};
use irs_model::input::{FieldError, present};
use irs_model::radiomap::{Progress, RadioMap, Unit, WorkError};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;

/// The longest robot name taken.
pub const MAX_NAME_CHARS: usize = 64;

/// What a fleet plan asks, beyond its map.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FleetQuery {
    /// The robots in priority order (the first is planned first).
    pub robots: Vec<RobotSpec>,
    /// The unit of the thresholds and of the values answered (default: the map's, dB).
    #[serde(default, deserialize_with = "present")]
    pub unit: Option<Unit>,
    /// Δt (s), default Δ/V_max.
    #[serde(default, deserialize_with = "present")]
    pub dt_s: Option<f64>,
    /// The latest arrival (s), default twice the longest route alone plus 64 steps.
    #[serde(default, deserialize_with = "present")]
    pub horizon_s: Option<f64>,
    /// `noma` or `oma`: robots served by one AP share its power, each needing its rate
    /// (`unit` bps_hz or mbps); absent, each robot has its AP to itself.
    #[serde(default, deserialize_with = "present")]
    pub access: Option<Access>,
}

/// One robot of a [`FleetQuery`].
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RobotSpec {
    /// Its name, echoed in the answer (default `robot-<index>`).
    #[serde(default, deserialize_with = "present")]
    pub name: Option<String>,
    /// Where it starts (x, y) (m): with `goal`, a robot to plan.
    #[serde(default, deserialize_with = "present")]
    pub start: Option<[f64; 2]>,
    /// Where it goes (x, y) (m).
    #[serde(default, deserialize_with = "present")]
    pub goal: Option<[f64; 2]>,
    /// Instead of `start` and `goal`, its route as poses [x, y, t] (m, m, s from the plan's
    /// start), t strictly increasing: checked as given, not planned.
    #[serde(default, deserialize_with = "present")]
    pub route: Option<Vec<[f64; 3]>>,
    /// Its requirement at every step, in the query's unit.
    pub threshold: f64,
}

/// A fleet plan as answered.
#[derive(Debug, Clone, Serialize)]
pub struct FleetAnswer {
    /// The map planned on.
    pub map_id: String,
    /// The robots' names in request order.
    pub names: Vec<String>,
    /// Per robot, its route step by step (empty when it is not served).
    pub waypoints: Vec<Vec<TimedWaypoint>>,
    /// The plan: robots, timeline (phases to 1e-4 rad) and violations.
    #[serde(flatten)]
    pub plan: FleetPlan,
}

/// One step of a robot's route.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TimedWaypoint {
    /// The step k.
    pub step: usize,
    /// k·Δt (s).
    pub time_s: f64,
    /// x of its cell's centre (m).
    pub x: f64,
    /// y of its cell's centre (m).
    pub y: f64,
    /// Heading (rad): that of its next move (the last move's once arrived or waiting).
    pub yaw_rad: f64,
    /// The serving AP.
    pub ap: usize,
    /// What it gets, in the plan's unit, with the IRS configuration of this step.
    pub value: f64,
}

/// Phases are written to 10⁻⁴ rad as path answers write them by default: their gains differ
/// from those reported (computed before rounding) by less than 10⁻⁶ dB.
const PHASE_STEP_RAD: f64 = 1e-4;

/// Plans `query` on `map`, the gain map of `scenario`, whose robot's V_max every robot drives
/// at and whose SRUs take part with `access`. Errors name the field (`robots[2].start`, `unit`,
/// `dt_s`, …); cancelling `progress` stops the search.
pub fn plan(
    scenario: &Scenario,
    map: &RadioMap,
    query: &FleetQuery,
    progress: &Progress,
) -> Result<FleetAnswer, WorkError> {
    let (robots, names) = requests(query)?;
    let options = options(scenario, map, query);
    let mut plan = fleet::plan_fleet(map, &scenario.srus, &robots, options, progress)?;
    for instant in &mut plan.timeline {
        for theta in instant.phases.iter_mut().flatten() {
            let rounded = (*theta / PHASE_STEP_RAD).round() * PHASE_STEP_RAD;
            *theta = if rounded >= TAU { 0.0 } else { rounded };
        }
    }
    let waypoints = (0..robots.len()).map(|r| waypoints(&plan, r)).collect();
    Ok(FleetAnswer {
        map_id: map.id.clone(),
        names,
        waypoints,
        plan,
    })
}

/// Every check [`plan`] makes before its search ([`fleet::check_fleet`]): a service runs it
/// before it admits a plan as a job.
pub fn check(scenario: &Scenario, map: &RadioMap, query: &FleetQuery) -> Result<(), FieldError> {
    let (robots, _) = requests(query)?;
    fleet::check_fleet(map, &scenario.srus, &robots, options(scenario, map, query))
}

/// The plan's options: the query's, with the scenario's V_max.
fn options(scenario: &Scenario, map: &RadioMap, query: &FleetQuery) -> FleetOptions {
    FleetOptions {
        unit: query.unit.unwrap_or(map.native_unit()),
        v_max_mps: scenario.mru.v_max_mps,
        dt_s: query.dt_s,
        horizon_s: query.horizon_s,
        access: query.access,
    }
}

/// The robots as the model takes them, and their names (unique; `robot-<index>` by default).
fn requests(query: &FleetQuery) -> Result<(Vec<RobotRequest>, Vec<String>), FieldError> {
    let mut robots = Vec::with_capacity(query.robots.len());
    let mut names = Vec::with_capacity(query.robots.len());
    for (r, spec) in query.robots.iter().enumerate() {
        let field = |f: &str| format!("robots[{r}].{f}");
        let motion = match (spec.start, spec.goal, &spec.route) {
            (Some(start), Some(goal), None) => {
                for (name, p) in [("start", start), ("goal", goal)] {
                    if !p.iter().all(|v| v.is_finite()) {
                        return Err(FieldError::new(field(name), "coordinates must be finite"));
                    }
                }
                Motion::Trip { start, goal }
            }
            (None, None, Some(route)) => Motion::Route(route.clone()),
            (_, _, Some(_)) => {
                return Err(FieldError::new(
                    field("route"),
                    "give either a route or a start and a goal, not both",
                ));
            }
            (None, _, None) => {
                return Err(FieldError::new(
                    field("start"),
                    "give a start and a goal, or a route",
                ));
            }
            (Some(_), None, None) => {
                return Err(FieldError::new(
                    field("goal"),
                    "give a start and a goal, or a route",
                ));
            }
        };
        if !spec.threshold.is_finite() {
            return Err(FieldError::new(
                field("threshold"),
                "must be a finite number",
            ));
        }
        let name = match &spec.name {
            Some(n) if n.is_empty() || n.chars().count() > MAX_NAME_CHARS => {
                return Err(FieldError::new(
                    field("name"),
                    format!("must have 1 to {MAX_NAME_CHARS} characters"),
                ));
            }
            Some(n) => n.clone(),
            None => format!("robot-{r}"),
        };
        if names.contains(&name) {
            return Err(FieldError::new(field("name"), format!("{name:?} is taken")));
        }
        names.push(name);
        robots.push(RobotRequest {
            motion,
            threshold: spec.threshold,
        });
    }
    Ok((robots, names))
}

/// Robot `r`'s steps from its start to its arrival, with headings.
fn waypoints(plan: &FleetPlan, r: usize) -> Vec<TimedWaypoint> {
    let Some(arrival) = plan.robots[r].arrival_step else {
        return Vec::new();
    };
    let states: Vec<_> = plan.timeline[..=arrival]
        .iter()
        .map(|i| {
            (
                i.step,
                i.time_s,
                i.robots[r].expect("a served robot is at every step"),
            )
        })
        .collect();
    let mut out: Vec<TimedWaypoint> = Vec::with_capacity(states.len());
    // The heading of the next move that changes cell, or the last one's.
    let mut heading = 0.0;
    for k in (0..states.len()).rev() {
        let (_, _, here) = states[k];
        if let Some((_, _, next)) = states.get(k + 1).copied()
            && (next.i, next.j) != (here.i, here.j)
        {
            heading = (next.y - here.y).atan2(next.x - here.x);
        }
        let (step, time_s, _) = states[k];
        out.push(TimedWaypoint {
            step,
            time_s,
            x: here.x,
            y: here.y,
            yaw_rad: heading,
            ap: here.ap,
            value: here.value,
        });
    }
    out.reverse();
    // Once arrived, or while waiting at the end, keep the last move's heading.
    let last_move = (1..states.len())
        .rev()
        .find(|&k| (states[k].2.i, states[k].2.j) != (states[k - 1].2.i, states[k - 1].2.j));
    if let Some(k) = last_move {
        let yaw = (states[k].2.y - states[k - 1].2.y).atan2(states[k].2.x - states[k - 1].2.x);
        out[k..].iter_mut().for_each(|w| w.yaw_rad = yaw);
    }
    out
}
