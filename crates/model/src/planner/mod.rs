//! Communication-aware paths over a radio map (docs/model.md §6, paper Section II-D): path and
//! sweep queries, asked as `query` says and answered as `answer` says. The searches
//! themselves live in [`graph`] and `any_angle`.

mod answer;
mod any_angle;
mod bottleneck;
pub mod graph;
mod jump;
mod query;
mod queue;
pub mod route_graph;

pub use answer::{Endpoint, Handover, PathAnswer, SweepAnswer, SweepPoint, Waypoint};
pub use query::{MAX_TOLERANCE_M, PathOptions, PathShape, Threshold};

pub use any_angle::AnyAnglePath;
pub use bottleneck::Bottlenecks;
pub use graph::{CellGraph, Infeasible, Path};
pub use jump::JumpIndex;

use crate::input::FieldError;
use crate::radiomap::{Cancelled, CellConfig, Progress, RadioMap, Unit, WorkError};
use crate::scenario::Grid;
use std::borrow::Cow;

pub(crate) fn endpoint(
    grid: &Grid,
    field: &str,
    p: [f64; 2],
) -> Result<(usize, Endpoint), FieldError> {
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
            moved: false,
            node: None,
        },
    ))
}

/// Moves an end whose cell is not `usable` to the nearest usable cell whose centre lies within
/// `tolerance_m` of the requested point (ties to the lower flat index); unchanged when its own
/// cell is usable, the tolerance is 0 or no cell within it is usable.
fn relocate(
    grid: &Grid,
    (cell, end): (usize, Endpoint),
    tolerance_m: f64,
    usable: impl Fn(usize) -> bool,
) -> (usize, Endpoint) {
    if tolerance_m <= 0.0 || usable(cell) {
        return (cell, end);
    }
    let [px, py] = end.requested;
    // At most the grid's side: a tolerance of many cells is the whole grid, not an overflow.
    let reach = ((tolerance_m / grid.resolution_m).ceil() as usize)
        .saturating_add(1)
        .min(grid.nx.max(grid.ny));
    // Rings of cells r steps from the end's own (Chebyshev distance), nearest first. The point
    // lies within half a cell of its cell's centre, so every centre on ring r is at least
    // (r − ½)·Δ from it: once that exceeds the best distance found, or the tolerance, no
    // further ring can do better. With a 2 m tolerance on a 2 cm grid the whole square is 41 000
    // cells; the rings usually stop after a few hundred.
    let (ei, ej) = (end.i as isize, end.j as isize);
    let (nx, ny) = (grid.nx as isize, grid.ny as isize);
    let mut best: Option<(f64, usize)> = None;
    let consider = |best: &mut Option<(f64, usize)>, i: isize, j: isize| {
        if i < 0 || j < 0 || i >= nx || j >= ny {
            return;
        }
        let (i, j) = (i as usize, j as usize);
        let c = grid.index(i, j);
        // Whether the cell is usable first: an end deep in an obstacle looks at thousands of
        // cells that are not (40 000 within 2 m on a 2 cm grid), and measuring each one's
        // distance was 5 % of a server's CPU under path queries with a tolerance.
        if !usable(c) {
            return;
        }
        let [x, y] = grid.centre(i, j);
        let d = (x - px).hypot(y - py);
        // Ties to the lower flat index, whatever order the rings visit cells in.
        if d <= tolerance_m && best.is_none_or(|b| (d, c) < b) {
            *best = Some((d, c));
        }
    };
    for r in 0..=reach as isize {
        let nearest = (r as f64 - 0.5) * grid.resolution_m;
        if nearest > tolerance_m || best.is_some_and(|(d, _)| nearest > d) {
            break;
        }
        for i in ei - r..=ei + r {
            if (i - ei).abs() == r {
                for j in ej - r..=ej + r {
                    consider(&mut best, i, j);
                }
            } else {
                consider(&mut best, i, ej - r);
                consider(&mut best, i, ej + r);
            }
        }
    }
    match best {
        Some((_, c)) => {
            let (i, j) = grid.cell_of(c);
            let [x, y] = grid.centre(i, j);
            (
                c,
                Endpoint {
                    x,
                    y,
                    i,
                    j,
                    snapped: true,
                    moved: true,
                    ..end
                },
            )
        }
        None => (cell, end),
    }
}

pub(crate) fn graph<'m>(map: &'m RadioMap, values: &'m [f64]) -> CellGraph<'m> {
    CellGraph {
        grid: &map.grid,
        values,
        occupied: &map.occupied,
    }
}

/// A map's values in one [`Unit`], their widest-path index and their jump point index: what
/// path and sweep queries on a map search, built once per map and unit (the service keeps it
/// with the map).
#[derive(Debug, Clone)]
pub struct UnitIndex {
    unit: Unit,
    /// The values in `unit`; `None` when they are the map's own.
    converted: Option<Vec<f64>>,
    bottlenecks: Bottlenecks,
    jumps: JumpIndex,
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
        let graph = graph(map, values);
        let bottlenecks = Bottlenecks::new(&graph);
        let jumps = JumpIndex::new(&graph);
        jumps.fill(&graph);
        Ok(UnitIndex {
            unit,
            converted,
            bottlenecks,
            jumps,
        })
    }

    /// The values in the index's unit; `map` must be the map the index was built from.
    pub fn values<'m>(&'m self, map: &'m RadioMap) -> &'m [f64] {
        self.converted.as_deref().unwrap_or(&map.values)
    }

    /// Heap bytes held, for a cache's weigher.
    pub fn bytes(&self) -> usize {
        self.bottlenecks.bytes()
            + self.jumps.bytes()
            + self
                .converted
                .as_ref()
                .map_or(0, |v| v.capacity() * std::mem::size_of::<f64>())
    }
}

/// Plans the shortest feasible path on a map (start/goal snapped to the nearest cell centre),
/// with the threshold and the values in `unit`, finding the widest-path threshold by a search
/// and the path on a jump point index built for the query: the cheaper way for one query on a
/// map.
pub fn plan(
    map: &RadioMap,
    unit: Unit,
    options: PathOptions,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    let values = map.values_in(unit)?;
    plan_with(
        map,
        (unit, &values, options),
        start,
        goal,
        threshold,
        v_max_mps,
        None,
    )
}

/// [`plan`] in the index's unit, the widest-path threshold read from the [`UnitIndex`] and a
/// grid path found by jump point search on it: the cheaper way for a map that answers many
/// queries.
pub fn plan_indexed(
    map: &RadioMap,
    index: &UnitIndex,
    options: PathOptions,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    let values = index.values(map);
    plan_with(
        map,
        (index.unit, values, options),
        start,
        goal,
        threshold,
        v_max_mps,
        Some(index),
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

/// A route: its waypoints as (flat cell index, point), the indices of its vertices among them,
/// and its length (m).
struct Route {
    points: Vec<(usize, [f64; 2])>,
    vertices: Vec<usize>,
    distance_m: f64,
}

/// The route of a feasible path as its waypoints' cells and points, and its length (m): the
/// 8-connected path's cell centres (found on `jumps` when given, else on an index built for the
/// query), or an any-angle
/// path's entry points and vertex centres.
fn route(
    graph: &CellGraph,
    jumps: Option<&JumpIndex>,
    shape: PathShape,
    start: usize,
    goal: usize,
    threshold: f64,
) -> Result<Route, Infeasible> {
    let grid = graph.grid;
    let centre = |c: usize| {
        let (i, j) = grid.cell_of(c);
        grid.centre(i, j)
    };
    match shape {
        PathShape::Grid => {
            let path = match jumps {
                Some(jumps) => jumps.shortest_path(graph, start, goal, threshold)?,
                None => graph.shortest_path(start, goal, threshold)?,
            };
            let points: Vec<_> = path.cells.iter().map(|&c| (c, centre(c))).collect();
            // A vertex wherever the step (Δi, Δj) changes, with both ends.
            let step = |k: usize| {
                let (a, b) = (grid.cell_of(path.cells[k]), grid.cell_of(path.cells[k + 1]));
                (b.0 as isize - a.0 as isize, b.1 as isize - a.1 as isize)
            };
            let n = points.len();
            let vertices = (0..n)
                .filter(|&k| k == 0 || k + 1 == n || step(k - 1) != step(k))
                .collect();
            Ok(Route {
                points,
                vertices,
                distance_m: path.distance_m,
            })
        }
        PathShape::RouteGraph => unreachable!("plan_with refuses route_graph before routing"),
        PathShape::AnyAngle => {
            let path = graph.any_angle_path(start, goal, threshold)?;
            let mut points = vec![(start, centre(start))];
            let mut vertices = vec![0];
            for pair in path.vertices.windows(2) {
                let (a, b) = (centre(pair[0]), centre(pair[1]));
                any_angle::segment_cells(
                    grid.cell_of(pair[0]),
                    grid.cell_of(pair[1]),
                    |i, j, interior, t| {
                        if interior && t > 0.0 {
                            let point = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                            points.push((grid.index(i, j), point));
                        }
                        true
                    },
                );
                // The vertex itself, where the route turns (or ends).
                vertices.push(points.len());
                points.push((pair[1], b));
            }
            Ok(Route {
                points,
                vertices,
                distance_m: path.distance_m,
            })
        }
    }
}

/// Fills a feasible answer's route: a waypoint per (cell, point) with its cell's value and
/// configuration (worked out once for consecutive points in one cell, as a vertex cell's entry
/// and centre are), their poses, the route's vertices and its handovers.
fn follow(
    answer: &mut PathAnswer,
    map: &RadioMap,
    values: &[f64],
    points: &[(usize, [f64; 2])],
    vertices: Vec<usize>,
    v_max_mps: f64,
) {
    let mut last: Option<(usize, CellConfig)> = None;
    answer.waypoints = points
        .iter()
        .map(|&(c, [x, y])| {
            let (i, j) = map.grid.cell_of(c);
            let config = match &last {
                Some((cell, config)) if *cell == c => config.clone(),
                _ => map.cell_config(c),
            };
            last = Some((c, config.clone()));
            Waypoint {
                x,
                y,
                i,
                j,
                value: values[c],
                yaw_rad: 0.0,
                distance_m: 0.0,
                time_s: 0.0,
                config,
            }
        })
        .collect();
    set_poses(&mut answer.waypoints, v_max_mps);
    answer.vertices = vertices;
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

fn plan_with(
    map: &RadioMap,
    (unit, values, options): (Unit, &[f64], PathOptions),
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
    index: Option<&UnitIndex>,
) -> Result<PathAnswer, FieldError> {
    if options.shape == PathShape::RouteGraph {
        return Err(FieldError::new(
            "path_shape",
            "a route_graph path is planned on the scenario's graph (route_graph::plan_on_graph)",
        ));
    }
    let graph = graph(map, values);
    // With a tolerance, an end in an obstacle or below the threshold moves to the nearest cell
    // that is neither ("max": the nearest free cell with a value).
    let usable = |c: usize| match threshold {
        Threshold::Value(t) => graph.is_feasible(c, t),
        Threshold::Max => !map.occupied[c] && values[c] > f64::NEG_INFINITY,
    };
    let (s, start) = relocate(
        &map.grid,
        endpoint(&map.grid, "start", start)?,
        options.tolerance_m,
        usable,
    );
    let (g, goal) = relocate(
        &map.grid,
        endpoint(&map.grid, "goal", goal)?,
        options.tolerance_m,
        usable,
    );
    let widest = match index {
        Some(index) => index.bottlenecks.widest_path_threshold(values, s, g),
        None => graph.widest_path_threshold(s, g),
    };
    let applied = match threshold {
        Threshold::Value(v) => Some(v),
        Threshold::Max => widest,
    };
    let result = match applied {
        Some(t) => route(&graph, index.map(|x| &x.jumps), options.shape, s, g, t),
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
        path_shape: options.shape,
        distance_m: None,
        travel_time_s: None,
        max_feasible_threshold: widest,
        start,
        goal,
        frame_id: DEFAULT_FRAME.to_string(),
        waypoints: Vec::new(),
        vertices: Vec::new(),
        handovers: Vec::new(),
    };
    if let Ok(Route {
        points,
        vertices,
        distance_m,
    }) = result
    {
        answer.distance_m = Some(distance_m);
        answer.travel_time_s = Some(distance_m / v_max_mps);
        follow(&mut answer, map, values, &points, vertices, v_max_mps);
    }
    Ok(answer)
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
            let r = index.jumps.shortest_path(&graph, s, g, t);
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
            Default::default(),
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
            Default::default(),
            [-10.0, 0.0],
            [-10.0, 0.0],
            Threshold::Max,
            v,
        )
        .unwrap();
        assert_eq!(alone.waypoints.len(), 1);
        assert_eq!(alone.waypoints[0].yaw_rad, 0.0);
    }

    /// An any-angle answer on the paper floor: shorter than the grid path at the same
    /// threshold, its waypoints on the segments between its vertices (each cell's entry point,
    /// then the vertex centres), every waypoint's cell meeting the threshold, and its poses
    /// adding up to its length.
    #[test]
    fn any_angle_answers_follow_their_segments() {
        let scenario = crate::scenario::Scenario::builtin("paper-single-user").unwrap();
        let key =
            crate::radiomap::MapKey::gain("x", &scenario, crate::phases::PhaseMode::Continuous)
                .unwrap();
        let map = crate::radiomap::build(&scenario, &key, "x".into(), &Default::default()).unwrap();
        let (start, goal) = ([-10.0, 0.0], [10.0, 0.0]);
        let gamma = Threshold::Value(-61.0);
        let grid = plan(
            &map,
            Unit::GainDb,
            Default::default(),
            start,
            goal,
            gamma,
            1.0,
        )
        .unwrap();
        let any = plan(
            &map,
            Unit::GainDb,
            PathOptions::any_angle(),
            start,
            goal,
            gamma,
            1.0,
        )
        .unwrap();
        assert!(grid.feasible && any.feasible);
        assert_eq!(any.path_shape, PathShape::AnyAngle);
        let (g, a) = (grid.distance_m.unwrap(), any.distance_m.unwrap());
        assert!(a < g, "any-angle {a} m vs grid {g} m");
        let w = &any.waypoints;
        let last = w.last().unwrap();
        assert!((last.distance_m - a).abs() < 1e-9);
        assert_eq!((w[0].i, w[0].j), (any.start.i, any.start.j));
        assert_eq!(*any.vertices.last().unwrap(), w.len() - 1);
        for v in any.vertices.windows(2) {
            let (p, q) = (&w[v[0]], &w[v[1]]);
            for r in &w[v[0]..=v[1]] {
                // On the segment p → q: no cross-track offset, between its ends.
                let cross = (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x);
                assert!(cross.abs() < 1e-9, "{cross}");
                assert!(r.value >= -61.0);
            }
        }
        // Vertices sit at cell centres.
        for &k in &any.vertices {
            let [x, y] = map.grid.centre(w[k].i, w[k].j);
            assert!((w[k].x - x).abs() < 1e-12 && (w[k].y - y).abs() < 1e-12);
        }
        assert!(any.vertices.len() < grid.vertices.len());
    }

    /// An end inside an obstacle moves to the nearest feasible cell within `tolerance_m` (the
    /// brute force over every cell agrees), and says so; beyond the tolerance nothing moves and
    /// the answer says why there is no path. A goal below the threshold moves the same way.
    #[test]
    fn ends_move_to_the_nearest_feasible_cell_within_the_tolerance() {
        let scenario = crate::scenario::Scenario::builtin("small-test").unwrap();
        let key =
            crate::radiomap::MapKey::gain("x", &scenario, crate::phases::PhaseMode::Continuous)
                .unwrap();
        let map = crate::radiomap::build(&scenario, &key, "x".into(), &Default::default()).unwrap();
        let inside = [3.0, 2.0];
        let with = |tolerance_m: f64, goal: [f64; 2], threshold: Threshold| {
            let options = PathOptions {
                tolerance_m,
                ..PathOptions::default()
            };
            plan(&map, Unit::GainDb, options, inside, goal, threshold, 1.0).unwrap()
        };
        let stuck = with(0.9, [0.5, 0.5], Threshold::Max);
        assert_eq!(stuck.reason, Some(Infeasible::StartOccupied));
        assert!(!stuck.start.moved);
        let moved = with(1.0, [0.5, 0.5], Threshold::Max);
        assert!(moved.feasible && moved.start.moved && moved.start.snapped);
        let nearest = (0..map.grid.cells())
            .filter(|&c| !map.occupied[c])
            .map(|c| {
                let (i, j) = map.grid.cell_of(c);
                let [x, y] = map.grid.centre(i, j);
                (x - inside[0]).hypot(y - inside[1])
            })
            .fold(f64::INFINITY, f64::min);
        let d = (moved.start.x - inside[0]).hypot(moved.start.y - inside[1]);
        assert!((d - nearest).abs() < 1e-12 && d <= 1.0, "{d} vs {nearest}");
        assert_eq!(moved.waypoints[0].x, moved.start.x);
        // A goal below the threshold: the nearest cell meeting it, within the tolerance. The
        // threshold lies between the goal cell's value and the best value within 1 m of it.
        let goal = [0.5, 0.5];
        let centre_of = |c: usize| {
            let (i, j) = map.grid.cell_of(c);
            map.grid.centre(i, j)
        };
        let near = |c: usize| {
            let [x, y] = centre_of(c);
            (x - goal[0]).hypot(y - goal[1])
        };
        let g0 = map.grid.index(1, 1);
        let best_near = (0..map.grid.cells())
            .filter(|&c| !map.occupied[c] && near(c) <= 1.0)
            .map(|c| map.values[c])
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(
            best_near > map.values[g0],
            "the goal cell is a local maximum"
        );
        let gamma = (best_near + map.values[g0]) / 2.0;
        let expected = (0..map.grid.cells())
            .filter(|&c| !map.occupied[c] && map.values[c] >= gamma && near(c) <= 1.0)
            .map(near)
            .fold(f64::INFINITY, f64::min);
        let answer = with(1.0, goal, Threshold::Value(gamma));
        assert!(answer.goal.moved, "{:?}", answer.reason);
        let g = map.grid.index(answer.goal.i, answer.goal.j);
        assert!(map.values[g] >= gamma);
        assert!((near(g) - expected).abs() < 1e-12);
        let refused = with(0.0, goal, Threshold::Value(gamma));
        assert_eq!(refused.reason, Some(Infeasible::StartOccupied));
    }

    /// The rings stop early; every cell of the square within the tolerance is the brute force,
    /// nearest first and ties to the lower flat index. Random grids, usable sets, points (off
    /// centre, near the edges) and tolerances of 0–12 cells.
    #[test]
    fn relocation_by_rings_is_the_nearest_usable_cell_of_the_square() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(0x51_7CC1_B727_220A);
        let mut next = move || rng.random::<u64>();
        for _ in 0..3000 {
            let (nx, ny) = (1 + next() as usize % 30, 1 + next() as usize % 30);
            let grid = Grid {
                nx,
                ny,
                x_min: -1.0,
                y_min: 2.0,
                resolution_m: 0.25,
            };
            let share = next() % 100;
            let usable: Vec<bool> = (0..nx * ny).map(|_| next() % 100 < share).collect();
            let unit = |k: u64| (k % 10_000) as f64 / 10_000.0;
            let p = [
                grid.x_min + unit(next()) * nx as f64 * 0.25,
                grid.y_min + unit(next()) * ny as f64 * 0.25,
            ];
            let tolerance = unit(next()) * 3.0;
            let Ok(end) = endpoint(&grid, "start", p) else {
                continue;
            };
            let (cell, moved) = relocate(&grid, end.clone(), tolerance, |c| usable[c]);
            let expected = if usable[end.0] {
                Some(end.0)
            } else {
                (0..nx * ny)
                    .filter(|&c| usable[c])
                    .map(|c| {
                        let (i, j) = grid.cell_of(c);
                        let [x, y] = grid.centre(i, j);
                        ((x - p[0]).hypot(y - p[1]), c)
                    })
                    .filter(|&(d, _)| d <= tolerance && tolerance > 0.0)
                    .min_by(|a, b| a.partial_cmp(b).unwrap())
                    .map(|(_, c)| c)
            };
            assert_eq!(cell, expected.unwrap_or(end.0), "{p:?} within {tolerance}");
            assert_eq!(moved.moved, expected.is_some_and(|c| c != end.0));
        }
    }

    #[test]
    fn thresholds_parse_as_in_json() {
        assert_eq!("max".parse::<Threshold>(), Ok(Threshold::Max));
        assert_eq!("-63.5".parse::<Threshold>(), Ok(Threshold::Value(-63.5)));
        assert!("NaN".parse::<Threshold>().is_err());
        assert!("maximum".parse::<Threshold>().is_err());
    }
}
