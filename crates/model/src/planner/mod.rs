//! Communication-aware paths over a radio map (docs/model.md §6, paper Section II-D): path and
//! sweep queries and the answers they return. The searches themselves live in [`graph`].

mod bottleneck;
pub mod graph;
mod queue;

pub use bottleneck::Bottlenecks;
pub use graph::{CellGraph, Infeasible, Path};

use crate::input::{FieldError, Scalar, parse_finite};
use crate::radiomap::{Cancelled, CellConfig, Progress, RadioMap, SurfaceRadians, Unit, WorkError};
use crate::scenario::Grid;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::str::FromStr;

/// The QoS threshold of a path query: a value in the query's unit, or the largest feasible one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// γ in the query's [`Unit`] (by default the map's: dB on gain maps, bit/s/Hz on rate maps).
    Value(f64),
    /// The largest γ for which any path joins start and goal (the widest-path value, §6).
    Max,
}

impl Serialize for Threshold {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Threshold::Value(v) => s.serialize_f64(*v),
            Threshold::Max => s.serialize_str("max"),
        }
    }
}

impl FromStr for Threshold {
    type Err = String;
    /// `"max"` or a finite number, as in `?threshold=` and `--threshold`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "max" => Ok(Threshold::Max),
            number => parse_finite(number)
                .map(Threshold::Value)
                .map_err(|e| format!("expected a number or \"max\": {e}")),
        }
    }
}

impl<'de> Deserialize<'de> for Threshold {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match crate::input::deserialize_scalar(d)? {
            Scalar::Text(s) if s == "max" => Ok(Threshold::Max),
            Scalar::Number(n, _) if n.is_finite() => Ok(Threshold::Value(n)),
            Scalar::Number(..) => Err(serde::de::Error::custom(
                "threshold must be a finite number",
            )),
            Scalar::Text(s) => Err(serde::de::Error::custom(format!(
                "expected a number or \"max\", got {s:?}"
            ))),
            Scalar::Other(other) => Err(serde::de::Error::custom(format!(
                "expected a number or \"max\", got {other}"
            ))),
        }
    }
}

/// Where a requested point landed on the grid.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Endpoint {
    /// The point as given (x, y) (m).
    pub requested: [f64; 2],
    /// x of the cell centre it snapped to (m).
    pub x: f64,
    /// y of the cell centre it snapped to (m).
    pub y: f64,
    /// The cell's index along x.
    pub i: usize,
    /// The cell's index along y.
    pub j: usize,
    /// True when the requested point was not itself a cell centre.
    pub snapped: bool,
}

/// One waypoint of a path and the configuration to apply there (phases held as `P`, see
/// [`CellConfig`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Waypoint<P = SurfaceRadians> {
    /// x of the cell centre (m).
    pub x: f64,
    /// y of the cell centre (m).
    pub y: f64,
    /// The cell's index along x.
    pub i: usize,
    /// The cell's index along y.
    pub j: usize,
    /// The map's value at this cell, in the query's unit.
    pub value: f64,
    /// The robot's heading here (rad, counter-clockwise from +x, in (−π, π]): that of the move
    /// to the next waypoint; at the goal, that of the last move (0 on a one-cell path).
    pub yaw_rad: f64,
    /// The path's length from the start to here (m).
    pub distance_m: f64,
    /// When the robot reaches this waypoint driving at V_max from the start (s).
    pub time_s: f64,
    /// What to configure here (serving AP, IRS phases; on rate maps the power split and decoding
    /// order), flattened into the waypoint's JSON.
    #[serde(flatten)]
    pub config: CellConfig<P>,
}

/// Where a path changes its serving AP (several APs): between waypoint `waypoint − 1` and
/// `waypoint`, at (x, y) — the first waypoint served by `to`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Handover {
    /// Index of the first waypoint served by `to`.
    pub waypoint: usize,
    /// x of that waypoint (m).
    pub x: f64,
    /// y of that waypoint (m).
    pub y: f64,
    /// The AP serving the waypoint before (an index into the scenario's APs).
    pub from: usize,
    /// The AP serving from this waypoint on.
    pub to: usize,
}

/// The answer to a path query; the same body from the CLI and the API once its phases are
/// written (`P`, see [`CellConfig`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PathAnswer<P = SurfaceRadians> {
    /// The id of the map the path was planned on.
    pub map_id: String,
    /// The unit of values and thresholds, written as its symbol ([`Unit::symbol`]): the
    /// query's unit, by default the map's (`dB` on gain maps, `bit/s/Hz` on rate maps).
    #[serde(serialize_with = "unit_symbol")]
    pub unit: Unit,
    /// The threshold applied (for `"max"`, the largest feasible one).
    pub threshold: Option<f64>,
    /// Whether a path was found.
    pub feasible: bool,
    /// Why there is no path; `None` when feasible.
    pub reason: Option<Infeasible>,
    /// The path's length (m): orthogonal steps of Δ, diagonal ones of √2·Δ; `None` when infeasible.
    pub distance_m: Option<f64>,
    /// `distance_m` / V_max (s); `None` when infeasible.
    pub travel_time_s: Option<f64>,
    /// The largest threshold for which any path joins start and goal.
    pub max_feasible_threshold: Option<f64>,
    /// Where the start landed on the grid.
    pub start: Endpoint,
    /// Where the goal landed on the grid.
    pub goal: Endpoint,
    /// The frame the positions are in, as a ROS message names it (`map` unless the request
    /// names another).
    pub frame_id: String,
    /// The path's cells, start first and goal last (empty when infeasible).
    pub waypoints: Vec<Waypoint<P>>,
    /// The handovers along the path, in order (empty with one AP).
    pub handovers: Vec<Handover>,
}

/// One point of a threshold sweep (paper Figs. 7 and 9).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepPoint {
    /// γ, in the map's unit.
    pub threshold: f64,
    /// Whether a path exists at γ.
    pub feasible: bool,
    /// Why there is none; `None` when feasible.
    pub reason: Option<Infeasible>,
    /// The shortest path's length at γ (m); `None` when infeasible.
    pub distance_m: Option<f64>,
    /// `distance_m` / V_max (s); `None` when infeasible.
    pub travel_time_s: Option<f64>,
}

/// The answer to a sweep: distance versus threshold between two points (paper Figs. 7 and 9);
/// the same body from the CLI and the API.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepAnswer {
    /// The id of the map swept.
    pub map_id: String,
    /// The thresholds' unit, written as its symbol ([`Unit::symbol`]).
    #[serde(serialize_with = "unit_symbol")]
    pub unit: Unit,
    /// The largest threshold for which any path joins start and goal (`None`: none does).
    pub max_feasible_threshold: Option<f64>,
    /// Where the start landed on the grid.
    pub start: Endpoint,
    /// Where the goal landed on the grid.
    pub goal: Endpoint,
    /// One point per requested threshold, in the order given.
    pub points: Vec<SweepPoint>,
}

fn unit_symbol<S: serde::Serializer>(unit: &Unit, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(unit.symbol())
}

fn endpoint(grid: &Grid, field: &str, p: [f64; 2]) -> Result<(usize, Endpoint), FieldError> {
    let (i, j) = grid.snap(p[0], p[1]).ok_or_else(|| {
        FieldError::new(field, format!("({}, {}) lies outside the room", p[0], p[1]))
    })?;
    let [x, y] = grid.centre(i, j);
    let snapped = (x - p[0]).abs() > 1e-9 || (y - p[1]).abs() > 1e-9;
    Ok((
        grid.index(i, j),
        Endpoint {
            requested: p,
            x,
            y,
            i,
            j,
            snapped,
        },
    ))
}

fn graph<'m>(map: &'m RadioMap, values: &'m [f64]) -> CellGraph<'m> {
    CellGraph {
        grid: &map.grid,
        values,
        occupied: &map.occupied,
    }
}

/// A map's values in one [`Unit`] and their widest-path index: what path and sweep queries on
/// a map search, built once per map and unit (the service keeps it with the map).
#[derive(Debug, Clone)]
pub struct UnitIndex {
    unit: Unit,
    /// The values in `unit`; `None` when they are the map's own.
    converted: Option<Vec<f64>>,
    bottlenecks: Bottlenecks,
}

impl UnitIndex {
    /// The index of `map`'s values in `unit`; an error names `unit` when the map cannot give
    /// its values in it ([`RadioMap::values_in`]).
    pub fn new(map: &RadioMap, unit: Unit) -> Result<UnitIndex, FieldError> {
        let converted = match map.values_in(unit)? {
            Cow::Borrowed(_) => None,
            Cow::Owned(values) => Some(values),
        };
        let values = converted.as_deref().unwrap_or(&map.values);
        let bottlenecks = Bottlenecks::new(&graph(map, values));
        Ok(UnitIndex {
            unit,
            converted,
            bottlenecks,
        })
    }

    /// The unit of the values.
    pub fn unit(&self) -> Unit {
        self.unit
    }

    /// The values in the index's unit; `map` must be the map the index was built from.
    pub fn values<'m>(&'m self, map: &'m RadioMap) -> &'m [f64] {
        self.converted.as_deref().unwrap_or(&map.values)
    }

    /// Heap bytes held, for a cache's weigher.
    pub fn bytes(&self) -> usize {
        self.bottlenecks.bytes()
            + self
                .converted
                .as_ref()
                .map_or(0, |v| v.capacity() * std::mem::size_of::<f64>())
    }
}

/// Plans the shortest feasible path on a map (start/goal snapped to the nearest cell centre),
/// with the threshold and the values in `unit`, finding the widest-path threshold by a search:
/// the cheaper way for one query on a map.
pub fn plan(
    map: &RadioMap,
    unit: Unit,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    let values = map.values_in(unit)?;
    plan_with(
        map,
        (unit, &values),
        start,
        goal,
        threshold,
        v_max_mps,
        |graph, s, g| graph.widest_path_threshold(s, g),
    )
}

/// [`plan`] in the index's unit, the widest-path threshold read from the [`UnitIndex`]: the
/// cheaper way for a map that answers many queries.
pub fn plan_indexed(
    map: &RadioMap,
    index: &UnitIndex,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    let values = index.values(map);
    plan_with(
        map,
        (index.unit, values),
        start,
        goal,
        threshold,
        v_max_mps,
        |_, s, g| index.bottlenecks.widest_path_threshold(values, s, g),
    )
}

/// The frame a path's positions are in unless a request names another: the map frame of a
/// ROS robot (REP 105).
pub const DEFAULT_FRAME: &str = "map";

/// Fills each waypoint's heading (towards the next; the goal keeps the last move's), its
/// distance from the start along the path and the time to reach it at `v_max_mps`.
fn set_poses<P>(waypoints: &mut [Waypoint<P>], v_max_mps: f64) {
    let mut travelled = 0.0;
    let mut heading = 0.0;
    for k in 0..waypoints.len() {
        if k > 0 {
            let (dx, dy) = (
                waypoints[k].x - waypoints[k - 1].x,
                waypoints[k].y - waypoints[k - 1].y,
            );
            travelled += dx.hypot(dy);
        }
        if let Some(next) = waypoints.get(k + 1) {
            heading = (next.y - waypoints[k].y).atan2(next.x - waypoints[k].x);
        }
        let w = &mut waypoints[k];
        (w.yaw_rad, w.distance_m, w.time_s) = (heading, travelled, travelled / v_max_mps);
    }
}

fn plan_with(
    map: &RadioMap,
    (unit, values): (Unit, &[f64]),
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
    widest_path_threshold: impl FnOnce(&CellGraph, usize, usize) -> Option<f64>,
) -> Result<PathAnswer, FieldError> {
    let (s, start) = endpoint(&map.grid, "start", start)?;
    let (g, goal) = endpoint(&map.grid, "goal", goal)?;
    let graph = graph(map, values);
    let widest = widest_path_threshold(&graph, s, g);
    let applied = match threshold {
        Threshold::Value(v) => Some(v),
        Threshold::Max => widest,
    };
    let result = match applied {
        Some(t) => graph.shortest_path(s, g, t),
        None => Err(if map.occupied[s] {
            Infeasible::StartOccupied
        } else if map.occupied[g] {
            Infeasible::GoalOccupied
        } else {
            Infeasible::Disconnected
        }),
    };
    let mut answer = PathAnswer {
        map_id: map.id.clone(),
        unit,
        threshold: applied,
        feasible: result.is_ok(),
        reason: result.as_ref().err().copied(),
        distance_m: None,
        travel_time_s: None,
        max_feasible_threshold: widest,
        start,
        goal,
        frame_id: DEFAULT_FRAME.to_string(),
        waypoints: Vec::new(),
        handovers: Vec::new(),
    };
    if let Ok(path) = result {
        answer.distance_m = Some(path.distance_m);
        answer.travel_time_s = Some(path.distance_m / v_max_mps);
        answer.waypoints = path
            .cells
            .iter()
            .map(|&c| {
                let (i, j) = map.grid.cell_of(c);
                let [x, y] = map.grid.centre(i, j);
                Waypoint {
                    x,
                    y,
                    i,
                    j,
                    value: values[c],
                    yaw_rad: 0.0,
                    distance_m: 0.0,
                    time_s: 0.0,
                    config: map.cell_config(c),
                }
            })
            .collect();
        set_poses(&mut answer.waypoints, v_max_mps);
        answer.handovers = answer
            .waypoints
            .windows(2)
            .enumerate()
            .filter(|(_, pair)| pair[0].config.ap != pair[1].config.ap)
            .map(|(k, pair)| Handover {
                waypoint: k + 1,
                x: pair[1].x,
                y: pair[1].y,
                from: pair[0].config.ap,
                to: pair[1].config.ap,
            })
            .collect();
    }
    Ok(answer)
}

impl<P> PathAnswer<P> {
    /// The same answer with every waypoint's phases held as `f` makes them.
    pub fn map_phases<Q>(self, mut f: impl FnMut(P) -> Q) -> PathAnswer<Q> {
        PathAnswer {
            waypoints: self
                .waypoints
                .into_iter()
                .map(|w| Waypoint {
                    x: w.x,
                    y: w.y,
                    i: w.i,
                    j: w.j,
                    value: w.value,
                    yaw_rad: w.yaw_rad,
                    distance_m: w.distance_m,
                    time_s: w.time_s,
                    config: w.config.map_phases(&mut f),
                })
                .collect(),
            map_id: self.map_id,
            unit: self.unit,
            threshold: self.threshold,
            feasible: self.feasible,
            reason: self.reason,
            distance_m: self.distance_m,
            travel_time_s: self.travel_time_s,
            max_feasible_threshold: self.max_feasible_threshold,
            start: self.start,
            goal: self.goal,
            frame_id: self.frame_id,
            handovers: self.handovers,
        }
    }
}

/// Distance versus threshold for a list of thresholds in the index's unit, in one request, on a
/// map whose [`UnitIndex`] is at hand (a sweep is a query of the service, which keeps it).
/// `progress` counts the thresholds done; cancelling it stops the sweep before the next
/// threshold.
pub fn sweep(
    map: &RadioMap,
    index: &UnitIndex,
    start: [f64; 2],
    goal: [f64; 2],
    thresholds: &[f64],
    v_max_mps: f64,
    progress: &Progress,
) -> Result<SweepAnswer, WorkError> {
    let (s, start) = endpoint(&map.grid, "start", start)?;
    let (g, goal) = endpoint(&map.grid, "goal", goal)?;
    let values = index.values(map);
    let graph = graph(map, values);
    progress.start(thresholds.len());
    let points = thresholds
        .iter()
        .map(|&t| {
            if progress.is_cancelled() {
                return Err(Cancelled);
            }
            let r = graph.shortest_path(s, g, t);
            progress.advance(1);
            Ok(SweepPoint {
                threshold: t,
                feasible: r.is_ok(),
                reason: r.as_ref().err().copied(),
                distance_m: r.as_ref().ok().map(|p| p.distance_m),
                travel_time_s: r.as_ref().ok().map(|p| p.distance_m / v_max_mps),
            })
        })
        .collect::<Result<_, Cancelled>>()?;
    Ok(SweepAnswer {
        map_id: map.id.clone(),
        unit: index.unit,
        max_feasible_threshold: index.bottlenecks.widest_path_threshold(values, s, g),
        start,
        goal,
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each waypoint's pose follows from the path: its heading is that of the move to the next
    /// waypoint (the goal keeps the last), its distance adds up the moves to the answer's
    /// length, and its time is the distance over V_max.
    #[test]
    fn waypoints_carry_their_heading_distance_and_time() {
        let scenario = crate::scenario::Scenario::builtin("paper-single-user").unwrap();
        let key =
            crate::radiomap::MapKey::gain("x", &scenario, crate::phases::PhaseMode::Continuous)
                .unwrap();
        let map = crate::radiomap::build(&scenario, &key, "x".into(), &Default::default()).unwrap();
        let v = 0.8;
        let path = plan(
            &map,
            Unit::GainDb,
            [-10.0, 0.0],
            [10.0, 0.0],
            Threshold::Max,
            v,
        )
        .unwrap();
        let w = &path.waypoints;
        assert!(w.len() > 10 && path.feasible);
        assert_eq!((w[0].distance_m, w[0].time_s), (0.0, 0.0));
        let last = w.last().unwrap();
        assert!((last.distance_m - path.distance_m.unwrap()).abs() < 1e-9);
        assert!((last.time_s - path.travel_time_s.unwrap()).abs() < 1e-9);
        for k in 0..w.len() - 1 {
            let (dx, dy) = (w[k + 1].x - w[k].x, w[k + 1].y - w[k].y);
            assert_eq!(w[k].yaw_rad, dy.atan2(dx), "waypoint {k}");
            // 8-connected moves: headings are multiples of π/4.
            let eighths = w[k].yaw_rad / std::f64::consts::FRAC_PI_4;
            assert!((eighths - eighths.round()).abs() < 1e-12, "{eighths}");
            let step = w[k + 1].distance_m - w[k].distance_m;
            assert!((step - dx.hypot(dy)).abs() < 1e-12);
            assert!((w[k + 1].time_s - w[k + 1].distance_m / v).abs() < 1e-12);
        }
        assert_eq!(
            last.yaw_rad,
            w[w.len() - 2].yaw_rad,
            "the goal keeps the last heading"
        );
        assert_eq!(path.frame_id, DEFAULT_FRAME);
        let alone = plan(
            &map,
            Unit::GainDb,
            [-10.0, 0.0],
            [-10.0, 0.0],
            Threshold::Max,
            v,
        )
        .unwrap();
        assert_eq!(alone.waypoints.len(), 1);
        assert_eq!(alone.waypoints[0].yaw_rad, 0.0);
    }

    #[test]
    fn thresholds_parse_as_in_json() {
        assert_eq!("max".parse::<Threshold>(), Ok(Threshold::Max));
        assert_eq!("-63.5".parse::<Threshold>(), Ok(Threshold::Value(-63.5)));
        assert!("NaN".parse::<Threshold>().is_err());
        assert!("maximum".parse::<Threshold>().is_err());
    }
}
