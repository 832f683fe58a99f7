//! Route graphs on a radio map (docs/model.md §6.4): every edge scored by the cells it crosses,
//! and routes on the graph whose every edge meets a threshold.
//!
//! An edge's cells are those whose closed square its polyline meets, found exactly by
//! sweeping the polyline's segments column by column ([`segment_crossings`]). A segment along
//! a cell boundary, or through a corner, meets the cells on both sides: the map's value is
//! constant over a cell, so on a boundary either cell's value may hold, and the worse one is the
//! one we can sign. Boundaries are widened by [`BOUNDARY_EPS`] of a cell so that a boundary
//! that decimal coordinates put a rounding error away still counts as touched.
//!
//! Routing is Dijkstra on the directed graph by polyline length, with every edge whose worst
//! value is below the threshold closed; the largest threshold at which any route exists is a
//! widest-path (bottleneck) search on the same graph.

use super::answer::{Endpoint, PathAnswer};
use super::{DEFAULT_FRAME, Infeasible, PathShape, Threshold, follow};
use crate::input::FieldError;
use crate::radiomap::{RadioMap, Unit};
use crate::scenario::Grid;
use crate::scenario::route_graph::{GraphEdge, GraphNode, RouteGraph};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// How far (in cells) a point may lie outside a cell's square and still meet it: far above
/// the rounding of decimal coordinates (~1e-15 of a cell), far below any distance a robot or
/// a map resolves.
pub const BOUNDARY_EPS: f64 = 1e-9;

/// A cell a segment meets, and the fractions of the segment between which it lies in the
/// cell's closed square (widened by [`BOUNDARY_EPS`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Crossing {
    /// The cell's flat index.
    pub cell: usize,
    /// Where the segment enters the square (fraction of the segment, 0 at its start).
    pub t_in: f64,
    /// Where it leaves.
    pub t_out: f64,
    /// True when the segment runs through the square's interior, false when it only touches
    /// its boundary (along an edge or at a corner).
    pub interior: bool,
}

/// The cells the segment from `p` to `q` meets, in the order the segment reaches them (by
/// `t_in`, then `t_out`), appended to `out`. Both points must lie in the grid's rectangle
/// (a cell's square extends half a cell beyond its centre).
pub(crate) fn segment_crossings(grid: &Grid, p: [f64; 2], q: [f64; 2], out: &mut Vec<Crossing>) {
    let first = out.len();
    let h = grid.resolution_m;
    // Cell coordinates: cell i covers u ∈ [i, i + 1].
    let (u0, v0) = ((p[0] - grid.x_min) / h + 0.5, (p[1] - grid.y_min) / h + 0.5);
    let (u1, v1) = ((q[0] - grid.x_min) / h + 0.5, (q[1] - grid.y_min) / h + 0.5);
    let (du, dv) = (u1 - u0, v1 - v0);
    let last_i = grid.nx as f64 - 1.0;
    let last_j = grid.ny as f64 - 1.0;
    let index_range = |a: f64, b: f64, last: f64| {
        let lo = (a.min(b) - BOUNDARY_EPS).floor().clamp(0.0, last) as usize;
        let hi = (a.max(b) + BOUNDARY_EPS).floor().clamp(0.0, last) as usize;
        (lo, hi)
    };
    // The fractions of the segment where the coordinate c0 + t·dc lies in [k − ε, k + 1 + ε].
    let slab_widened = |k: usize, c0: f64, dc: f64, eps: f64| -> (f64, f64) {
        if dc == 0.0 {
            return (0.0, 1.0);
        }
        let a = (k as f64 - eps - c0) / dc;
        let b = (k as f64 + 1.0 + eps - c0) / dc;
        (a.min(b).max(0.0), a.max(b).min(1.0))
    };
    let slab = |k: usize, c0: f64, dc: f64| slab_widened(k, c0, dc, BOUNDARY_EPS);
    let (i_lo, i_hi) = index_range(u0, u1, last_i);
    for i in i_lo..=i_hi {
        let (c_lo, c_hi) = slab(i, u0, du);
        if c_lo > c_hi {
            continue;
        }
        let (j_lo, j_hi) = index_range(v0 + c_lo * dv, v0 + c_hi * dv, last_j);
        for j in j_lo..=j_hi {
            let (r_lo, r_hi) = slab(j, v0, dv);
            let (t_in, t_out) = (c_lo.max(r_lo), c_hi.min(r_hi));
            if t_in > t_out {
                continue;
            }
            // Where the segment meets the square itself, not its widened boundary: the widening
            // decides which cells count, never where an entry point is written.
            let exact_in = slab_widened(i, u0, du, 0.0)
                .0
                .max(slab_widened(j, v0, dv, 0.0).0);
            let t_in = exact_in.clamp(t_in, t_out);
            let t_mid = 0.5 * (t_in + t_out);
            let (u, v) = (u0 + t_mid * du, v0 + t_mid * dv);
            let inside =
                |c: f64, k: usize| c > k as f64 + BOUNDARY_EPS && c < k as f64 + 1.0 - BOUNDARY_EPS;
            out.push(Crossing {
                cell: grid.index(i, j),
                t_in,
                t_out,
                interior: inside(u, i) && inside(v, j),
            });
        }
    }
    out[first..].sort_by(|a, b| {
        (a.t_in, a.t_out)
            .partial_cmp(&(b.t_in, b.t_out))
            .unwrap_or(Ordering::Equal)
    });
}

/// Where an edge changes its serving AP.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeHandover {
    /// Distance from the edge's start (m) where the first cell served by `to` is entered.
    pub distance_m: f64,
    /// That point (x, y) (m).
    pub at: [f64; 2],
    /// The AP serving before (an index into the scenario's APs).
    pub from: usize,
    /// The AP serving from there on.
    pub to: usize,
}

/// What an edge meets on a map.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeScore {
    /// The polyline's length (m).
    pub length_m: f64,
    /// The lowest value of the cells the edge meets, in the map's values' unit; `None` when one
    /// of them has no value (occupied, or a rate map's cell that no configuration serves).
    pub worst: Option<f64>,
    /// The first cell (i, j) along the edge where that value (or the first cell without a
    /// value) is met.
    pub worst_cell: (usize, usize),
    /// Where the edge reaches that cell (x, y) (m).
    pub worst_at: [f64; 2],
    /// How far along the edge it does (m).
    pub worst_distance_m: f64,
    /// Whether the edge meets an occupied cell (an obstacle, a wall, the floor plan's
    /// occupied or unknown pixels, widened by the robot's radius).
    pub crosses_obstacle: bool,
    /// The APs serving the edge's cells, in the order the edge meets them (a change is a
    /// handover); the cells it only touches are left out unless it touches nothing else.
    pub serving: Vec<usize>,
    /// The handovers along the edge, in order.
    pub handovers: Vec<EdgeHandover>,
    /// How many cells the edge meets.
    pub cells: usize,
}

impl EdgeScore {
    /// Whether a robot may drive the edge at `threshold`: every cell it meets has a value of at
    /// least `threshold` (so none is occupied).
    pub fn open_at(&self, threshold: f64) -> bool {
        self.worst.is_some_and(|w| w >= threshold)
    }
}

/// The cells an edge's polyline meets, in order along it: (crossing, distance of the
/// segment's start from the edge's start, the segment's ends).
fn edge_crossings(
    grid: &Grid,
    points: &[[f64; 2]],
    mut visit: impl FnMut(&Crossing, f64, [f64; 2], [f64; 2]),
) {
    let mut crossings = Vec::new();
    let mut travelled = 0.0;
    for pair in points.windows(2) {
        crossings.clear();
        segment_crossings(grid, pair[0], pair[1], &mut crossings);
        for c in &crossings {
            visit(c, travelled, pair[0], pair[1]);
        }
        travelled += (pair[1][0] - pair[0][0]).hypot(pair[1][1] - pair[0][1]);
    }
}

fn lerp(a: [f64; 2], b: [f64; 2], t: f64) -> [f64; 2] {
    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
}

/// Scores every edge of `graph` on `map` with the map's values in some unit (`values`, one
/// per cell, NaN where a cell has none).
pub fn score_edges(map: &RadioMap, values: &[f64], graph: &RouteGraph) -> Vec<EdgeScore> {
    graph
        .edges
        .iter()
        .map(|edge| score_polyline(map, values, &edge.points))
        .collect()
}

/// A roadmap for a site without a route graph: nodes at the centres of every `step`-th cell
/// along x and y that is free (and, with a threshold, meets it), each joined both ways to its
/// lattice neighbours east, north, north-east and south-east wherever the straight edge between
/// them is open (meets no occupied cell; with a threshold, no cell below it). Nodes left without
/// an edge are dropped. Node ids are their indices, edge ids continue after them (unique across
/// both, as Nav2 asks).
pub fn roadmap(
    map: &RadioMap,
    values: &[f64],
    step: usize,
    threshold: Option<f64>,
) -> (Vec<GraphNode>, Vec<GraphEdge>) {
    let grid = &map.grid;
    let step = step.max(1);
    let usable = |c: usize| {
        !map.occupied[c] && !values[c].is_nan() && threshold.is_none_or(|t| values[c] >= t)
    };
    let (ni, nj) = ((grid.nx - 1) / step + 1, (grid.ny - 1) / step + 1);
    let cell = |a: usize, b: usize| grid.index(a * step, b * step);
    let centre = |a: usize, b: usize| grid.centre(a * step, b * step);
    let mut pairs = Vec::new();
    for a in 0..ni {
        for b in 0..nj {
            if !usable(cell(a, b)) {
                continue;
            }
            for (da, db) in [(1isize, 0isize), (0, 1), (1, 1), (1, -1)] {
                let (a2, b2) = (a as isize + da, b as isize + db);
                if a2 < 0 || b2 < 0 || a2 as usize >= ni || b2 as usize >= nj {
                    continue;
                }
                let (a2, b2) = (a2 as usize, b2 as usize);
                if !usable(cell(a2, b2)) {
                    continue;
                }
                let score = score_polyline(map, values, &[centre(a, b), centre(a2, b2)]);
                let open = match threshold {
                    Some(t) => score.open_at(t),
                    None => score.worst.is_some(),
                };
                if open {
                    pairs.push(((a, b), (a2, b2)));
                }
            }
        }
    }
    let mut index = std::collections::HashMap::new();
    let mut nodes = Vec::new();
    let mut node = |p: (usize, usize), nodes: &mut Vec<GraphNode>| {
        *index.entry(p).or_insert_with(|| {
            nodes.push(GraphNode {
                id: nodes.len().to_string(),
                position: centre(p.0, p.1),
            });
            nodes.len() - 1
        })
    };
    let ends: Vec<(usize, usize)> = pairs
        .iter()
        .map(|&(p, q)| (node(p, &mut nodes), node(q, &mut nodes)))
        .collect();
    let mut edges = Vec::with_capacity(2 * ends.len());
    for (a, b) in ends {
        for (from, to) in [(a, b), (b, a)] {
            edges.push(GraphEdge {
                id: (nodes.len() + edges.len()).to_string(),
                from,
                to,
                points: vec![nodes[from].position, nodes[to].position],
            });
        }
    }
    (nodes, edges)
}

fn score_polyline(map: &RadioMap, values: &[f64], points: &[[f64; 2]]) -> EdgeScore {
    let grid = &map.grid;
    let mut score = EdgeScore {
        length_m: 0.0,
        worst: None,
        worst_cell: (0, 0),
        worst_at: points[0],
        worst_distance_m: 0.0,
        crosses_obstacle: false,
        serving: Vec::new(),
        handovers: Vec::new(),
        cells: 0,
    };
    // The running minimum, a cell without a value counting as −∞.
    let mut worst = f64::INFINITY;
    let mut all_serving = Vec::new();
    let mut interior_serving: Vec<(usize, f64, [f64; 2])> = Vec::new();
    edge_crossings(grid, points, |c, travelled, a, b| {
        let length = (b[0] - a[0]).hypot(b[1] - a[1]);
        let at = lerp(a, b, c.t_in);
        let distance = travelled + c.t_in * length;
        let occupied = map.occupied[c.cell];
        let value = match values[c.cell] {
            v if occupied || v.is_nan() => f64::NEG_INFINITY,
            v => v,
        };
        score.crosses_obstacle |= occupied;
        score.cells += 1;
        if value < worst {
            worst = value;
            score.worst_cell = grid.cell_of(c.cell);
            score.worst_at = at;
            score.worst_distance_m = distance;
        }
        let ap = map.serving_ap(c.cell);
        all_serving.push((ap, distance, at));
        if c.interior {
            interior_serving.push((ap, distance, at));
        }
    });
    score.worst = Some(worst).filter(|w| *w > f64::NEG_INFINITY);
    let sequence = if interior_serving.is_empty() {
        all_serving
    } else {
        interior_serving
    };
    for (ap, distance_m, at) in sequence {
        match score.serving.last() {
            Some(&from) if from != ap => score.handovers.push(EdgeHandover {
                distance_m,
                at,
                from,
                to: ap,
            }),
            Some(_) => continue,
            None => {}
        }
        score.serving.push(ap);
    }
    score.length_m = points
        .windows(2)
        .map(|p| (p[1][0] - p[0][0]).hypot(p[1][1] - p[0][1]))
        .sum();
    score
}

/// A heap entry ordered by `key` (smallest first for Dijkstra; the widest path negates its
/// widths), ties to the lower node.
#[derive(PartialEq)]
struct Entry {
    key: f64,
    node: u32,
}
impl Eq for Entry {}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .key
            .total_cmp(&self.key)
            .then_with(|| other.node.cmp(&self.node))
    }
}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// A route on the graph: its edges in order (indices into [`RouteGraph::edges`]) and length.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphRoute {
    /// The edges driven, in order (empty when start and goal are one node).
    pub edges: Vec<usize>,
    /// The sum of their lengths (m).
    pub distance_m: f64,
}

/// A graph's edges with their scores laid out for the searches: each node's outgoing edges
/// contiguous (compressed rows), with the end node, length and worst value beside each, so a
/// search reads three flat arrays instead of chasing every edge's polyline and score. Building
/// it costs about half a search; one built for several searches saves that each time.
#[derive(Debug, Clone)]
pub struct ScoredGraph {
    /// Node k's outgoing edges are slots first[k]..first[k + 1].
    first: Vec<u32>,
    /// Per slot: the edge's index in the graph.
    edge: Vec<u32>,
    /// Per slot: the node it reaches.
    to: Vec<u32>,
    /// Per slot: its length (m).
    length: Vec<f64>,
    /// Per slot: its worst value, −∞ for an edge meeting a cell without a value.
    worst: Vec<f64>,
    /// Per edge: the node it leaves (to walk a route back).
    from: Vec<u32>,
}

impl ScoredGraph {
    /// The search layout of `graph` with `scores` (one per edge, [`score_edges`]).
    pub fn new(graph: &RouteGraph, scores: &[EdgeScore]) -> ScoredGraph {
        let n = graph.nodes.len();
        let mut first = vec![0u32; n + 1];
        for e in &graph.edges {
            first[e.from + 1] += 1;
        }
        for k in 0..n {
            first[k + 1] += first[k];
        }
        let slots = graph.edges.len();
        let mut fill = first.clone();
        let (mut edge, mut to) = (vec![0u32; slots], vec![0u32; slots]);
        let (mut length, mut worst) = (vec![0.0; slots], vec![0.0; slots]);
        for (k, e) in graph.edges.iter().enumerate() {
            let slot = fill[e.from] as usize;
            fill[e.from] += 1;
            // Graphs are read with at most MAX_GRAPH_NODES nodes and MAX_GRAPH_EDGES edges.
            edge[slot] = u32::try_from(k).expect("fewer than 2³² edges");
            to[slot] = u32::try_from(e.to).expect("fewer than 2³² nodes");
            length[slot] = scores[k].length_m;
            worst[slot] = scores[k].worst.unwrap_or(f64::NEG_INFINITY);
        }
        ScoredGraph {
            first,
            edge,
            to,
            length,
            worst,
            from: graph.edges.iter().map(|e| e.from as u32).collect(),
        }
    }

    fn slots(&self, node: usize) -> std::ops::Range<usize> {
        self.first[node] as usize..self.first[node + 1] as usize
    }

    /// The shortest route from node `start` to node `goal` over edges open at `threshold`
    /// (every cell they meet at least `threshold`; Dijkstra by length); `None` when no such
    /// route exists.
    pub fn shortest_route(&self, start: usize, goal: usize, threshold: f64) -> Option<GraphRoute> {
        let n = self.first.len() - 1;
        let mut distance = vec![f64::INFINITY; n];
        let mut via = vec![u32::MAX; n];
        let mut heap = BinaryHeap::new();
        distance[start] = 0.0;
        heap.push(Entry {
            key: 0.0,
            node: start as u32,
        });
        while let Some(Entry { key, node }) = heap.pop() {
            let node = node as usize;
            if key > distance[node] {
                continue;
            }
            if node == goal {
                break;
            }
            for slot in self.slots(node) {
                // −∞ (no value) is below every threshold.
                if self.worst[slot] < threshold {
                    continue;
                }
                let next = self.to[slot] as usize;
                let d = key + self.length[slot];
                if d < distance[next] {
                    distance[next] = d;
                    via[next] = self.edge[slot];
                    heap.push(Entry {
                        key: d,
                        node: next as u32,
                    });
                }
            }
        }
        if !distance[goal].is_finite() {
            return None;
        }
        let mut edges = Vec::new();
        let mut node = goal;
        while node != start {
            let e = via[node] as usize;
            edges.push(e);
            node = self.from[e] as usize;
        }
        edges.reverse();
        Some(GraphRoute {
            edges,
            distance_m: distance[goal],
        })
    }

    /// The largest threshold at which some route joins `start` to `goal`: the widest path,
    /// the best over routes of their worst edge. `None` when no route exists at any threshold;
    /// +∞ when start and goal are one node.
    pub fn widest_threshold(&self, start: usize, goal: usize) -> Option<f64> {
        let mut width = vec![f64::NEG_INFINITY; self.first.len() - 1];
        let mut heap = BinaryHeap::new();
        width[start] = f64::INFINITY;
        heap.push(Entry {
            key: f64::NEG_INFINITY,
            node: start as u32,
        });
        while let Some(Entry { key, node }) = heap.pop() {
            let (w, node) = (-key, node as usize);
            if w < width[node] {
                continue;
            }
            if node == goal {
                return Some(w);
            }
            for slot in self.slots(node) {
                let through = w.min(self.worst[slot]);
                let next = self.to[slot] as usize;
                if through > width[next] {
                    width[next] = through;
                    heap.push(Entry {
                        key: -through,
                        node: next as u32,
                    });
                }
            }
        }
        None
    }
}

/// The route on a scenario's route graph from the node nearest `start` to the node nearest
/// `goal`, as a path answer (`path_shape` `route_graph`): a waypoint at every node and bend
/// it passes (its vertices) and where it enters each cell between them, each with the
/// configuration of its cell, as an any-angle path has. `scores` are the graph's edges scored
/// on `map` with `values` in `unit` ([`score_edges`]).
#[allow(clippy::too_many_arguments)]
pub fn plan_on_graph(
    map: &RadioMap,
    (unit, values): (Unit, &[f64]),
    graph: &RouteGraph,
    scores: &[EdgeScore],
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    let grid = &map.grid;
    let end = |field: &str, p: [f64; 2]| -> Result<(usize, Endpoint), FieldError> {
        if !p[0].is_finite() || !p[1].is_finite() {
            return Err(FieldError::new(field, "not a finite point"));
        }
        let node = graph.nearest_node(p).ok_or_else(|| {
            FieldError::new("path_shape", "the scenario's route graph has no nodes")
        })?;
        let position = graph.nodes[node].position;
        let (i, j) = grid
            .snap(position[0], position[1])
            .expect("a graph's nodes lie in the room (checked when it is read)");
        Ok((
            node,
            Endpoint {
                requested: p,
                x: position[0],
                y: position[1],
                i,
                j,
                snapped: position != p,
                moved: false,
                node: Some(graph.nodes[node].id.clone()),
            },
        ))
    };
    let (s, start) = end("start", start)?;
    let (g, goal) = end("goal", goal)?;
    let cell_value = |node: usize| {
        let (i, j) = grid
            .snap(graph.nodes[node].position[0], graph.nodes[node].position[1])
            .expect("in the room");
        let c = grid.index(i, j);
        Some(values[c]).filter(|v| !v.is_nan() && !map.occupied[c])
    };
    let searched = ScoredGraph::new(graph, scores);
    let widest = if s == g {
        cell_value(s)
    } else {
        searched.widest_threshold(s, g)
    };
    let applied = match threshold {
        Threshold::Value(v) => Some(v),
        Threshold::Max => widest,
    };
    let occupied = |node: usize| {
        let [x, y] = graph.nodes[node].position;
        let (i, j) = grid.snap(x, y).expect("in the room");
        map.occupied[grid.index(i, j)]
    };
    let result = match applied {
        _ if occupied(s) => Err(Infeasible::StartOccupied),
        _ if occupied(g) => Err(Infeasible::GoalOccupied),
        Some(t) if s == g => {
            if cell_value(s).is_some_and(|v| v >= t) {
                Ok(GraphRoute {
                    edges: vec![],
                    distance_m: 0.0,
                })
            } else {
                Err(Infeasible::StartBelowThreshold)
            }
        }
        Some(t) => searched
            .shortest_route(s, g, t)
            .ok_or(Infeasible::Disconnected),
        None => Err(Infeasible::Disconnected),
    };
    let mut answer = PathAnswer {
        map_id: map.id.clone(),
        unit,
        threshold: applied,
        feasible: result.is_ok(),
        reason: result.as_ref().err().copied(),
        path_shape: PathShape::RouteGraph,
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
    let Ok(route) = result else {
        return Ok(answer);
    };
    answer.distance_m = Some(route.distance_m);
    answer.travel_time_s = Some(route.distance_m / v_max_mps);
    let snap_cell = |p: [f64; 2]| {
        let (i, j) = grid.snap(p[0], p[1]).expect("in the room");
        grid.index(i, j)
    };
    let first = graph.nodes[s].position;
    let mut points: Vec<(usize, [f64; 2])> = vec![(snap_cell(first), first)];
    let mut vertices = vec![0];
    for &e in &route.edges {
        let edge = &graph.edges[e];
        for pair in edge.points.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let length = (b[0] - a[0]).hypot(b[1] - a[1]);
            if length == 0.0 {
                // Two nodes at one point: nothing to drive, no heading to give.
                continue;
            }
            let mut crossings = Vec::new();
            segment_crossings(grid, a, b, &mut crossings);
            for c in crossings.iter().filter(|c| c.interior) {
                let last = points.last_mut().expect("the start is first");
                if c.t_in * length <= 1e-9 {
                    // The segment leaves its start into this cell: a start on a cell boundary
                    // snapped to the neighbour drives this one, whose configuration applies.
                    last.0 = c.cell;
                } else if last.0 != c.cell {
                    points.push((c.cell, lerp(a, b, c.t_in)));
                }
            }
            vertices.push(points.len());
            points.push((snap_cell(b), b));
        }
    }
    follow(&mut answer, map, values, &points, vertices, v_max_mps);
    Ok(answer)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use crate::scenario::route_graph::{GraphEdge, GraphFormat, GraphNode, GraphSource};
    use proptest::prelude::*;
    use std::sync::Arc;

    fn grid(nx: usize, ny: usize, resolution_m: f64) -> Grid {
        Grid {
            nx,
            ny,
            x_min: 0.0,
            y_min: 0.0,
            resolution_m,
        }
    }

    /// Whether the closed segment (p, q) meets the closed square [a, b]², all in exact integers:
    /// their bounding boxes overlap and the square's corners do not all lie strictly on one
    /// side of the segment's line.
    fn meets_exactly(p: [i64; 2], q: [i64; 2], lo: [i64; 2], hi: [i64; 2]) -> bool {
        if p[0].max(q[0]) < lo[0] || p[0].min(q[0]) > hi[0] {
            return false;
        }
        if p[1].max(q[1]) < lo[1] || p[1].min(q[1]) > hi[1] {
            return false;
        }
        let side =
            |c: [i64; 2]| ((q[0] - p[0]) * (c[1] - p[1]) - (q[1] - p[1]) * (c[0] - p[0])).signum();
        let corners = [lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]].map(side);
        !(corners.iter().all(|&s| s > 0) || corners.iter().all(|&s| s < 0))
    }

    proptest! {
        /// The column sweep finds exactly the cells whose closed square the segment meets,
        /// decided in exact integer arithmetic, on points a 64th of a cell apart (so that
        /// segments run along boundaries and through corners often). Each cell once, in order.
        #[test]
        fn crossings_are_exactly_the_cells_met(
            a in (0i64..=64 * 9, 0i64..=64 * 7),
            b in (0i64..=64 * 9, 0i64..=64 * 7),
            coarse in any::<bool>(),
        ) {
            // On a coarse lattice (whole and half cells) boundaries and corners are met often.
            let snap = |v: i64| if coarse { v / 32 * 32 } else { v };
            let (a, b) = ((snap(a.0), snap(a.1)), (snap(b.0), snap(b.1)));
            // Grid of 10 × 8 cells of 0.25 m, centres at 0, 0.25, …: cell i spans
            // [(i − ½)Δ, (i + ½)Δ]; points in 64ths of a cell from −½ cell.
            let g = grid(10, 8, 0.25);
            let point = |(u, v): (i64, i64)| [(u as f64 / 64.0 - 0.5) * 0.25, (v as f64 / 64.0 - 0.5) * 0.25];
            let (p, q) = (point(a), point(b));
            let mut found = Vec::new();
            segment_crossings(&g, p, q, &mut found);
            let mut cells: Vec<usize> = found.iter().map(|c| c.cell).collect();
            for pair in found.windows(2) {
                prop_assert!(pair[0].t_in <= pair[1].t_in);
            }
            cells.sort();
            let before = cells.len();
            cells.dedup();
            prop_assert_eq!(before, cells.len(), "a cell met twice");
            let mut expected = Vec::new();
            for i in 0..10 {
                for j in 0..8 {
                    let lo = [i as i64 * 64, j as i64 * 64];
                    let hi = [lo[0] + 64, lo[1] + 64];
                    if meets_exactly([a.0, a.1], [b.0, b.1], lo, hi) {
                        expected.push(g.index(i, j));
                    }
                }
            }
            prop_assert_eq!(cells, expected);
        }
    }

    /// A graph on `nodes` with `edges` (from, to) drawn straight.
    fn graph(nodes: &[[f64; 2]], edges: &[(usize, usize)]) -> RouteGraph {
        RouteGraph {
            nodes: nodes
                .iter()
                .enumerate()
                .map(|(k, &position)| GraphNode {
                    id: k.to_string(),
                    position,
                })
                .collect(),
            edges: edges
                .iter()
                .enumerate()
                .map(|(k, &(from, to))| GraphEdge {
                    id: (100 + k).to_string(),
                    from,
                    to,
                    points: vec![nodes[from], nodes[to]],
                })
                .collect(),
            source: Arc::new(GraphSource {
                format: GraphFormat::Nav2GeoJson,
                level: None,
                document: "null".into(),
            }),
        }
    }

    /// Every simple route from `s` to `g`, as edge lists (exhaustive: small graphs only).
    fn simple_routes(graph: &RouteGraph, s: usize, g: usize) -> Vec<Vec<usize>> {
        fn walk(
            graph: &RouteGraph,
            at: usize,
            g: usize,
            seen: &mut Vec<bool>,
            route: &mut Vec<usize>,
            out: &mut Vec<Vec<usize>>,
        ) {
            if at == g {
                out.push(route.clone());
                return;
            }
            for (k, e) in graph.edges.iter().enumerate() {
                if e.from == at && !seen[e.to] {
                    seen[e.to] = true;
                    route.push(k);
                    walk(graph, e.to, g, seen, route, out);
                    route.pop();
                    seen[e.to] = false;
                }
            }
        }
        let mut seen = vec![false; graph.nodes.len()];
        seen[s] = true;
        let mut out = Vec::new();
        walk(graph, s, g, &mut seen, &mut Vec::new(), &mut out);
        out
    }

    fn score(length_m: f64, worst: Option<f64>) -> EdgeScore {
        EdgeScore {
            length_m,
            worst,
            worst_cell: (0, 0),
            worst_at: [0.0, 0.0],
            worst_distance_m: 0.0,
            crosses_obstacle: worst.is_none(),
            serving: vec![0],
            handovers: vec![],
            cells: 1,
        }
    }

    proptest! {
        /// Dijkstra and the widest-path search against every simple route of small random
        /// directed graphs with random edge lengths and worst values.
        #[test]
        fn graph_searches_match_every_simple_route(
            edges in proptest::collection::vec((0usize..6, 0usize..6, 1u32..20, proptest::option::weighted(0.9, -80i32..-40)), 0..16),
            s in 0usize..6,
            g in 0usize..6,
            threshold in -80i32..-40,
        ) {
            let nodes: Vec<[f64; 2]> = (0..6).map(|k| [k as f64, 0.0]).collect();
            let pairs: Vec<(usize, usize)> = edges.iter().map(|e| (e.0, e.1)).collect();
            let graph = graph(&nodes, &pairs);
            let scores: Vec<EdgeScore> = edges
                .iter()
                .map(|e| score(e.2 as f64, e.3.map(f64::from)))
                .collect();
            let routes = simple_routes(&graph, s, g);
            let t = f64::from(threshold);
            let best = routes
                .iter()
                .filter(|r| r.iter().all(|&e| scores[e].open_at(t)))
                .map(|r| r.iter().map(|&e| scores[e].length_m).sum::<f64>())
                .min_by(f64::total_cmp);
            let searched = ScoredGraph::new(&graph, &scores);
            let found = searched.shortest_route(s, g, t);
            prop_assert_eq!(found.as_ref().map(|r| r.distance_m), best);
            if let Some(route) = found {
                // The edges chain from s to g, every one open, and add up to the length.
                let mut at = s;
                for &e in &route.edges {
                    prop_assert_eq!(graph.edges[e].from, at);
                    prop_assert!(scores[e].open_at(t));
                    at = graph.edges[e].to;
                }
                prop_assert_eq!(at, g);
            }
            let widest = routes
                .iter()
                .filter_map(|r| {
                    r.iter()
                        .map(|&e| scores[e].worst)
                        .try_fold(f64::INFINITY, |w, e| e.map(|e| w.min(e)))
                })
                .max_by(f64::total_cmp);
            prop_assert_eq!(searched.widest_threshold(s, g), widest);
        }
    }

    fn paper_map() -> RadioMap {
        let scenario = Scenario::builtin("paper-single-user").unwrap();
        let key =
            crate::radiomap::MapKey::gain("x", &scenario, crate::phases::PhaseMode::Continuous)
                .unwrap();
        crate::radiomap::build(&scenario, &key, "x".into(), &Default::default()).unwrap()
    }

    /// On the paper floor: an edge through the central box crosses an obstacle and is closed
    /// at every threshold; an edge along open floor is scored by the lowest cell it meets,
    /// found by walking it densely; an edge along a cell boundary takes the worse side.
    #[test]
    fn edges_are_scored_by_the_cells_they_meet() {
        let map = paper_map();
        let nodes = [
            [-9.0, 0.0],
            [9.0, 0.0],
            [-9.0, -9.0],
            [9.0, -8.0],
            [-9.0, 8.25],
            [9.0, 8.25],
        ];
        let graph = graph(&nodes, &[(0, 1), (2, 3), (4, 5)]);
        let scores = score_edges(&map, &map.values, &graph);
        assert!(scores[0].crosses_obstacle && scores[0].worst.is_none());
        assert!(!scores[0].open_at(-1e9));
        let (i, j) = scores[0].worst_cell;
        assert!(map.occupied[map.grid.index(i, j)]);
        // Dense sampling meets every interior cell; the score's cells include them.
        let dense_min = |p: [f64; 2], q: [f64; 2]| {
            (0..=20_000)
                .map(|k| {
                    let [x, y] = lerp(p, q, k as f64 / 20_000.0);
                    let (i, j) = map.grid.snap(x, y).unwrap();
                    map.values[map.grid.index(i, j)]
                })
                .fold(f64::INFINITY, f64::min)
        };
        let open = &scores[1];
        assert!(!open.crosses_obstacle);
        let w = open.worst.unwrap();
        assert!(w <= dense_min(nodes[2], nodes[3]));
        assert_eq!(
            w,
            dense_min(nodes[2], nodes[3]),
            "a diagonal meets no cell only at a corner here"
        );
        assert!((open.length_m - 18.0f64.hypot(1.0)).abs() < 1e-12);
        // y = 8.25 is the boundary between rows 8.0 and 8.5: both rows count.
        let along = &scores[2];
        let rows = dense_min([-9.0, 8.0], [9.0, 8.0]).min(dense_min([-9.0, 8.5], [9.0, 8.5]));
        assert_eq!(along.worst, Some(rows));
        assert_eq!(along.serving, vec![0]);
        assert!(along.handovers.is_empty());
    }

    /// A route on the graph as a path answer: it goes round a closed edge, its vertices are the
    /// nodes, its waypoints meet the threshold, and its length is its edges'.
    #[test]
    fn graph_routes_avoid_closed_edges() {
        let map = paper_map();
        // 0 → 1 straight through the central box; 0 → 2 → 3 → 1 round the boxes to the north.
        let nodes = [[-9.0, 0.0], [9.0, 0.0], [-9.0, 8.5], [9.0, 8.5]];
        let graph = graph(&nodes, &[(0, 1), (0, 2), (2, 3), (3, 1)]);
        let scores = score_edges(&map, &map.values, &graph);
        let answer = plan_on_graph(
            &map,
            (Unit::GainDb, &map.values),
            &graph,
            &scores,
            [-9.1, 0.1],
            [9.0, 0.0],
            Threshold::Max,
            1.0,
        )
        .unwrap();
        assert!(answer.feasible);
        assert_eq!(answer.start.node.as_deref(), Some("0"));
        assert!(answer.start.snapped);
        assert_eq!(answer.goal.node.as_deref(), Some("1"));
        let expected = scores[1].length_m + scores[2].length_m + scores[3].length_m;
        assert!((answer.distance_m.unwrap() - expected).abs() < 1e-12);
        let last = answer.waypoints.last().unwrap();
        assert!((last.distance_m - expected).abs() < 1e-9);
        let threshold = answer.threshold.unwrap();
        let widest = scores[1..]
            .iter()
            .map(|s| s.worst.unwrap())
            .fold(f64::INFINITY, f64::min);
        assert_eq!(threshold, widest);
        assert!(answer.waypoints.iter().all(|w| w.value >= threshold));
        let vertices: Vec<[f64; 2]> = answer
            .vertices
            .iter()
            .map(|&k| [answer.waypoints[k].x, answer.waypoints[k].y])
            .collect();
        assert_eq!(vertices, vec![nodes[0], nodes[2], nodes[3], nodes[1]]);
        // One waypoint per cell entered between the vertices, each in its cell.
        for w in &answer.waypoints {
            let [cx, cy] = map.grid.centre(w.i, w.j);
            assert!((w.x - cx).abs() <= 0.25 + 1e-9 && (w.y - cy).abs() <= 0.25 + 1e-9);
        }
        // Above the widest threshold no route exists.
        let none = plan_on_graph(
            &map,
            (Unit::GainDb, &map.values),
            &graph,
            &scores,
            nodes[0],
            nodes[1],
            Threshold::Value(threshold + 1e-9),
            1.0,
        )
        .unwrap();
        assert_eq!(none.reason, Some(Infeasible::Disconnected));
        assert!(none.waypoints.is_empty());
    }

    /// A roadmap of the paper floor at 1 m: every node usable, every edge open at the threshold
    /// and paired with its reverse; routed on, it is never shorter than the 8-connected path
    /// between the same nodes (its edges are runs of 8-connected steps), and not much longer.
    #[test]
    fn roadmaps_are_open_and_routable() {
        let map = paper_map();
        let widest = super::super::plan(
            &map,
            Unit::GainDb,
            Default::default(),
            [-10.0, 0.0],
            [10.0, 0.0],
            Threshold::Max,
            1.0,
        )
        .unwrap()
        .threshold
        .unwrap();
        let t = widest - 3.0;
        let (nodes, edges) = roadmap(&map, &map.values, 2, Some(t));
        assert!(
            nodes.len() > 100 && edges.len() > 4 * nodes.len() / 2,
            "{} {}",
            nodes.len(),
            edges.len()
        );
        let graph = RouteGraph {
            nodes,
            edges,
            source: Arc::new(GraphSource {
                format: GraphFormat::Nav2GeoJson,
                level: None,
                document: "null".into(),
            }),
        };
        let scores = score_edges(&map, &map.values, &graph);
        assert!(scores.iter().all(|s| s.open_at(t) && !s.crosses_obstacle));
        for pair in graph.edges.chunks(2) {
            assert_eq!((pair[0].from, pair[0].to), (pair[1].to, pair[1].from));
        }
        let s = graph.nearest_node([-10.0, 0.0]).unwrap();
        let g = graph.nearest_node([10.0, 0.0]).unwrap();
        let route = ScoredGraph::new(&graph, &scores)
            .shortest_route(s, g, t)
            .expect("a route at 3 dB below the widest");
        let cell = |k: usize| {
            let [x, y] = graph.nodes[k].position;
            let (i, j) = map.grid.snap(x, y).unwrap();
            map.grid.index(i, j)
        };
        let cells = super::super::graph(&map, &map.values);
        let grid_path = cells.shortest_path(cell(s), cell(g), t).unwrap();
        assert!(route.distance_m >= grid_path.distance_m - 1e-9);
        assert!(
            route.distance_m <= 1.3 * grid_path.distance_m,
            "{} vs {}",
            route.distance_m,
            grid_path.distance_m
        );
    }

    /// A node on a cell boundary takes the configuration of the cell its edge drives through,
    /// not of the neighbour the boundary point snaps to; an occupied end node is named as such.
    #[test]
    fn a_route_from_a_boundary_drives_with_the_cell_it_enters() {
        let map = paper_map();
        // y = 8.25 lies between the rows of centres 8.0 and 8.5; the edge goes south.
        let nodes = [[-8.0, 8.25], [-8.0, 6.75], [0.0, 0.0]];
        let graph = graph(&nodes, &[(0, 1), (1, 2)]);
        let scores = score_edges(&map, &map.values, &graph);
        let plan = |goal: [f64; 2]| {
            plan_on_graph(
                &map,
                (Unit::GainDb, &map.values),
                &graph,
                &scores,
                nodes[0],
                goal,
                Threshold::Max,
                1.0,
            )
            .unwrap()
        };
        let answer = plan(nodes[1]);
        assert!(answer.feasible);
        let first = &answer.waypoints[0];
        assert_eq!((first.x, first.y), (-8.0, 8.25));
        assert_eq!(
            map.grid.centre(first.i, first.j),
            [-8.0, 8.0],
            "the cell driven through"
        );
        assert!(answer.waypoints.windows(2).all(|w| w[0].j >= w[1].j));
        // (0, 0) is inside the central box.
        assert_eq!(plan(nodes[2]).reason, Some(Infeasible::GoalOccupied));
    }
}
