//! What a path or sweep query returns: where its ends landed, the waypoints with their poses,
//! times and IRS configurations, the handovers, and the sweep's distance per threshold.

use super::{Infeasible, PathShape};
use crate::radiomap::{CellConfig, SurfaceRadians, Unit};
use serde::Serialize;

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
    /// True when the requested point's own cell was occupied or below the threshold and the
    /// nearest feasible cell within the query's `tolerance_m` was taken instead (x, y, i, j
    /// are that cell's).
    pub moved: bool,
    /// On a route graph, the id of the node the point went to (the nearest; x and y are its
    /// position, i and j its cell).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
}

/// One waypoint of a path and the configuration to apply from there on (phases held as `P`,
/// see [`CellConfig`]). A grid path has one per cell, at its centre. An any-angle path has one
/// where its route enters each cell it crosses (the cell's configuration applies from there),
/// and one at the centre of each vertex (its start, turns and goal), so the waypoints, joined in
/// order, are the route itself.
#[derive(Debug, Clone, PartialEq)]
pub struct Waypoint<P = SurfaceRadians> {
    /// x of the point (m): the cell's centre, or where an any-angle route enters the cell.
    pub x: f64,
    /// y of the point (m).
    pub y: f64,
    /// The cell's index along x.
    pub i: usize,
    /// The cell's index along y.
    pub j: usize,
    /// The map's value at this cell (at its centre), in the query's unit.
    pub value: f64,
    /// The robot's heading here (rad, counter-clockwise from +x, in (−π, π]): that of the move
    /// to the next waypoint; at the goal, that of the last move (0 on a one-cell path).
    pub yaw_rad: f64,
    /// The path's length from the start to here (m).
    pub distance_m: f64,
    /// When the robot reaches this waypoint driving at V_max from the start (s).
    pub time_s: f64,
    /// What to configure here (serving AP, IRS phases; on rate maps the power split and decoding
    /// order); its fields are the waypoint's in JSON.
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
/// written (`P`, see [`CellConfig`]; the body is written by `irs_answers::path_json`, its
/// fields in this order).
#[derive(Debug, Clone, PartialEq)]
pub struct PathAnswer<P = SurfaceRadians> {
    /// The id of the map the path was planned on.
    pub map_id: String,
    /// The unit of values and thresholds, written as its symbol ([`Unit::symbol`]): the
    /// query's unit, by default the map's (`dB` on gain maps, `bit/s/Hz` on rate maps).
    pub unit: Unit,
    /// The threshold applied (for `"max"`, the largest feasible one).
    pub threshold: Option<f64>,
    /// Whether a path was found.
    pub feasible: bool,
    /// Why there is no path; `None` when feasible.
    pub reason: Option<Infeasible>,
    /// The route's shape: `grid` or `any_angle`.
    pub path_shape: PathShape,
    /// The path's length (m): on a grid path orthogonal steps of Δ and diagonal ones of √2·Δ,
    /// on an any-angle path the sum of its segments; `None` when infeasible.
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
    /// Indices into `waypoints` of the route's vertices: the start, every point where the
    /// heading changes, the goal; the sparse polyline of the route.
    pub vertices: Vec<usize>,
    /// The handovers along the path, in order (empty with one AP).
    pub handovers: Vec<Handover>,
}

/// One point of a threshold sweep (paper Figs. 7 and 9).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepPoint {
    /// γ, in the sweep's unit.
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
            path_shape: self.path_shape,
            distance_m: self.distance_m,
            travel_time_s: self.travel_time_s,
            max_feasible_threshold: self.max_feasible_threshold,
            start: self.start,
            goal: self.goal,
            frame_id: self.frame_id,
            vertices: self.vertices,
            handovers: self.handovers,
        }
    }
}
