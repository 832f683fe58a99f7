//! The feasible map as a graph, and the searches on it (docs/model.md §6).
//!
//! The feasible map Π (paper eq. 14) marks the free cells whose value meets the threshold; the
//! graph joins each feasible cell to its feasible 8-neighbours with the Euclidean distance between
//! centres as weight (paper eqs. 15–16). The shortest path is found by jump point search
//! (`jump`); A* with the octile heuristic, which is admissible and consistent on this graph (so
//! it returns Dijkstra's distance), is its reference and gives any-angle paths their heuristic.
//!
//! One choice beyond the paper: a diagonal step may not cut the corner of an *occupied* cell (both
//! orthogonal neighbours must be free), because the segment between the two centres would graze
//! an obstacle. Cells that are merely below the threshold may be cut, as in the paper's Fig. 3.
//!
//! Beyond the paper, [`CellGraph::widest_path_threshold`] returns the largest threshold for which
//! any path exists (a bottleneck path: one Dijkstra-like pass maximising the minimum value along
//! the path).

use super::jump::JumpIndex;
use super::queue::BucketQueue;
use crate::scenario::Grid;
use serde::Serialize;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::Mutex;

/// Why no path exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Infeasible {
    /// The snapped start cell lies in an obstacle.
    StartOccupied,
    /// The snapped goal cell lies in an obstacle.
    GoalOccupied,
    /// The start cell's value is below γ (or null on a rate map).
    StartBelowThreshold,
    /// The goal cell's value is below γ (or null on a rate map).
    GoalBelowThreshold,
    /// Both ends are feasible, but no chain of feasible cells joins them.
    Disconnected,
}

/// A shortest path: the visited cells (flat indices, start first) and its length in metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    /// Flat cell indices (i·ny + j), start first and goal last.
    pub cells: Vec<usize>,
    /// Length (m): orthogonal steps of Δ, diagonal ones of √2·Δ.
    pub distance_m: f64,
}

/// The 8 neighbour offsets (di, dj) with their length in units of Δ: four orthogonal steps,
/// then four diagonal ones (a step's index is the direction a [`Node`] records).
pub(super) const NEIGHBOURS: [(isize, isize, f64); 8] = [
    (1, 0, 1.0),
    (-1, 0, 1.0),
    (0, 1, 1.0),
    (0, -1, 1.0),
    (1, 1, std::f64::consts::SQRT_2),
    (1, -1, std::f64::consts::SQRT_2),
    (-1, 1, std::f64::consts::SQRT_2),
    (-1, -1, std::f64::consts::SQRT_2),
];

/// A map's values seen as a graph: NaN marks an occupied (or unserviceable) cell.
#[derive(Debug, Clone, Copy)]
pub struct CellGraph<'a> {
    /// The grid the cells are laid on.
    pub grid: &'a Grid,
    /// Per cell (flat index i·ny + j): the map's value (dB or bit/s/Hz), NaN where none.
    pub values: &'a [f64],
    /// Per cell: true where an obstruction occupies the centre (never a vertex of the graph).
    pub occupied: &'a [bool],
}

impl<'a> CellGraph<'a> {
    /// Calls `visit(neighbour, its (i, j), direction)` for every neighbour of `cell` that is
    /// free and reachable without cutting an occupied corner; `direction` indexes
    /// [`NEIGHBOURS`]. The coordinates come along so that a search's heuristic needs no
    /// division per neighbour.
    #[inline]
    pub(crate) fn for_each_neighbour(
        &self,
        cell: usize,
        mut visit: impl FnMut(usize, (usize, usize), usize),
    ) {
        let (i, j) = self.grid.cell_of(cell);
        let (nx, ny) = (self.grid.nx, self.grid.ny);
        for (direction, &(di, dj, _)) in NEIGHBOURS.iter().enumerate() {
            // Off the grid on either side: a step below 0 wraps to a huge index.
            let (a, b) = (i.wrapping_add_signed(di), j.wrapping_add_signed(dj));
            if a >= nx || b >= ny {
                continue;
            }
            let n = a * ny + b;
            if self.occupied[n] {
                continue;
            }
            if di != 0 && dj != 0 && (self.occupied[a * ny + j] || self.occupied[i * ny + b]) {
                continue;
            }
            visit(n, (a, b), direction);
        }
    }

    /// Π_{i,j} of paper eq. 14.
    #[inline]
    pub fn is_feasible(&self, cell: usize, threshold: f64) -> bool {
        !self.occupied[cell] && self.values[cell] >= threshold
    }

    /// Shortest feasible path from `start` to `goal` (paper problem 13), or why there is none:
    /// jump point search on a [`JumpIndex`] built for this one query (a map that answers many
    /// keeps its index: [`JumpIndex::shortest_path`]).
    pub fn shortest_path(
        &self,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Result<Path, Infeasible> {
        self.check_ends(start, goal, threshold)?;
        JumpIndex::new(self).shortest_path(self, start, goal, threshold)
    }

    /// The same by A*: the reference the jump point search is tested against, a path of the
    /// same length though not always the same cells.
    pub fn a_star_path(
        &self,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Result<Path, Infeasible> {
        self.check_ends(start, goal, threshold)?;
        with_scratch(|scratch| {
            let (mut cells, length) = self.a_star(scratch, start, goal, threshold)?;
            cells.reverse();
            Ok(Path {
                cells,
                distance_m: length * self.grid.resolution_m,
            })
        })
    }

    /// A* from `from` to `to` (ends checked by the caller) in `scratch`, whose nodes keep
    /// every reached cell's shortest way from `from` found: the path's cells from `to` back
    /// to `from`, and its length in cells.
    pub(super) fn a_star(
        &self,
        scratch: &mut Scratch,
        from: usize,
        to: usize,
        threshold: f64,
    ) -> Result<(Vec<usize>, f64), Infeasible> {
        let heuristic = self.octile_to(to);
        let Scratch { nodes, open, .. } = scratch;
        nodes.reset(self.values.len());
        nodes.set(from, Node::reached(0, 0, 0, nodes.generation));
        let from_f = heuristic(self.grid.cell_of(from));
        open.reset(from_f);
        open.push(from_f, from as u32);
        // The bucket in which `to` was first settled: the search ends once it is empty.
        let mut goal_bucket = None;
        while let Some(cell) = open.pop() {
            if goal_bucket.is_some_and(|last| open.bucket() > last) {
                break;
            }
            let cell = cell as usize;
            let here = nodes.get(cell);
            if here.is_settled(nodes.generation) {
                continue; // stale: reached again by a shorter way, and expanded from there
            }
            nodes.set(cell, here.settled());
            if cell == to {
                goal_bucket.get_or_insert(open.bucket());
                continue;
            }
            let (orthogonal, diagonal) = here.steps();
            self.for_each_neighbour(cell, |n, at, direction| {
                let (a, b) = if direction < 4 {
                    (orthogonal + 1, diagonal)
                } else {
                    (orthogonal, diagonal + 1)
                };
                let candidate = length_in_cells(a, b);
                let there = nodes.get(n);
                if there.is_reached(nodes.generation) && candidate >= there.length() {
                    return;
                }
                if !self.is_feasible(n, threshold) {
                    return;
                }
                // A shorter way to a cell already expanded opens it again.
                nodes.set(n, Node::reached(a, b, direction, nodes.generation));
                open.push(candidate + heuristic(at), n as u32);
            });
        }
        let end = nodes.get(to);
        if !end.is_settled(nodes.generation) {
            return Err(Infeasible::Disconnected);
        }
        let mut path = vec![to];
        let ny = self.grid.ny as isize;
        let mut cell = to;
        while cell != from {
            let (di, dj, _) = NEIGHBOURS[nodes.get(cell).direction()];
            cell = cell.wrapping_add_signed(-(di * ny + dj));
            path.push(cell);
        }
        Ok((path, end.length()))
    }

    /// The largest threshold γ for which a feasible path from `start` to `goal` exists: the
    /// maximum over paths of the minimum value along the path. `None` if either end is occupied
    /// or no path of free cells joins them.
    pub fn widest_path_threshold(&self, start: usize, goal: usize) -> Option<f64> {
        if self.occupied[start] || self.occupied[goal] {
            return None;
        }
        let value = |c: usize| {
            if self.values[c].is_nan() {
                f64::NEG_INFINITY
            } else {
                self.values[c]
            }
        };
        // No path is wider than its narrower end: once the goal is reached at that width,
        // nothing can improve it (a one-step query then ends at once, in either direction).
        let ceiling = value(start).min(value(goal));
        let to_goal = self.octile_to(goal);
        with_scratch(|scratch| {
            let Scratch {
                nodes,
                widest_heap: heap,
                ..
            } = scratch;
            nodes.reset(self.values.len());
            // A node records the cell whose value is the width of the widest way found to it.
            let width = |nodes: &Nodes, c: usize| {
                let node = nodes.get(c);
                if node.is_reached(nodes.generation) {
                    value(node.bottleneck())
                } else {
                    f64::NEG_INFINITY
                }
            };
            heap.clear();
            nodes.set(start, Node::narrowed_at(start, nodes.generation));
            // Among entries of equal width the one nearer the goal goes first: widths tie on
            // every cell above a narrow end, and breaking the tie by cell index made the search
            // cost 1 ms one way and 37 ms the other on the 1001² floor.
            heap.push((
                OrdF64(value(start)),
                Reverse(OrdF64(to_goal(self.grid.cell_of(start)))),
                start,
            ));
            while let Some((OrdF64(b), _, cell)) = heap.pop() {
                let here = nodes.get(cell);
                if here.is_settled(nodes.generation) {
                    continue;
                }
                nodes.set(cell, here.settled());
                if cell == goal || width(nodes, goal) >= ceiling {
                    break;
                }
                let bottleneck = here.bottleneck();
                self.for_each_neighbour(cell, |n, at, _| {
                    let through = b.min(value(n));
                    if !nodes.get(n).is_settled(nodes.generation) && through > width(nodes, n) {
                        let narrowest = if value(n) < b { n } else { bottleneck };
                        nodes.set(n, Node::narrowed_at(narrowest, nodes.generation));
                        heap.push((OrdF64(through), Reverse(OrdF64(to_goal(at))), n));
                    }
                });
            }
            heap.clear();
            let width = width(nodes, goal);
            width.is_finite().then_some(width)
        })
    }

    /// The octile distance from a cell's (i, j) to `goal` in units of Δ (the shortest
    /// 8-connected length on an empty grid, so an admissible and consistent A* heuristic),
    /// with the goal's coordinates worked out once: the searches call it for every neighbour
    /// they push.
    fn octile_to(&self, goal: usize) -> impl Fn((usize, usize)) -> f64 + use<> {
        let (gi, gj) = self.grid.cell_of(goal);
        move |(i, j): (usize, usize)| {
            let (dx, dy) = (i.abs_diff(gi) as f64, j.abs_diff(gj) as f64);
            dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)
        }
    }

    pub(super) fn check_ends(
        &self,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Result<(), Infeasible> {
        if self.occupied[start] {
            return Err(Infeasible::StartOccupied);
        }
        if self.occupied[goal] {
            return Err(Infeasible::GoalOccupied);
        }
        if !self.is_feasible(start, threshold) {
            return Err(Infeasible::StartBelowThreshold);
        }
        if !self.is_feasible(goal, threshold) {
            return Err(Infeasible::GoalBelowThreshold);
        }
        Ok(())
    }
}

/// The length of a path of `orthogonal` steps of Δ and `diagonal` steps of √2·Δ, in cells.
/// Kept as the two counts, a path's length is exact up to this one rounding, however long the
/// path; equal counts are equal lengths, whatever the order of the steps.
#[inline]
pub(super) fn length_in_cells(orthogonal: u64, diagonal: u64) -> f64 {
    orthogonal as f64 + diagonal as f64 * std::f64::consts::SQRT_2
}

/// Bits of a [`Node`]'s fields, low to high.
const COUNT_BITS: u32 = 20;
const DIRECTION_BITS: u32 = 3;
const STAMP_SHIFT: u32 = 2 * COUNT_BITS + DIRECTION_BITS;
const COUNT_MASK: u64 = (1 << COUNT_BITS) - 1;
/// The largest generation a stamp holds (21 bits).
const MAX_STAMP: u32 = (1 << (64 - STAMP_SHIFT)) - 1;
// A simple path has fewer steps than the grid has cells, and a cell index fits a count.
const _: () = assert!(crate::scenario::MAX_GRID_CELLS <= 1 << COUNT_BITS);

/// One cell's search state in 8 bytes, so that a 1001² search's nodes take 8 MB (half the
/// cache footprint of an f64 length, a u32 predecessor and a u32 stamp).
/// - A*: the shortest way found, as its counts of orthogonal and diagonal steps (bits 0–19 and
///   20–39; the length is [`length_in_cells`]), and the direction of its last step (bits
///   40–42), from which the predecessor follows.
/// - The widest path: the cell whose value is the width of the widest way found (bits 0–19).
/// - Both: which search wrote the node (bits 43–63): its generation when reached, one more
///   once settled; an older stamp reads as unset.
#[derive(Debug, Clone, Copy)]
pub(super) struct Node(u64);

impl Node {
    #[inline]
    fn reached(orthogonal: u64, diagonal: u64, direction: usize, generation: u32) -> Node {
        Node(
            orthogonal
                | diagonal << COUNT_BITS
                | (direction as u64) << (2 * COUNT_BITS)
                | u64::from(generation) << STAMP_SHIFT,
        )
    }

    #[inline]
    fn narrowed_at(bottleneck: usize, generation: u32) -> Node {
        Node(bottleneck as u64 | u64::from(generation) << STAMP_SHIFT)
    }

    #[inline]
    fn stamp(self) -> u32 {
        (self.0 >> STAMP_SHIFT) as u32
    }

    #[inline]
    pub(super) fn is_reached(self, generation: u32) -> bool {
        self.stamp() >= generation
    }

    #[inline]
    fn is_settled(self, generation: u32) -> bool {
        self.stamp() == generation + 1
    }

    #[inline]
    fn settled(self) -> Node {
        Node(self.0 + (1 << STAMP_SHIFT))
    }

    #[inline]
    fn steps(self) -> (u64, u64) {
        (self.0 & COUNT_MASK, self.0 >> COUNT_BITS & COUNT_MASK)
    }

    #[inline]
    pub(super) fn length(self) -> f64 {
        let (orthogonal, diagonal) = self.steps();
        length_in_cells(orthogonal, diagonal)
    }

    #[inline]
    fn direction(self) -> usize {
        (self.0 >> (2 * COUNT_BITS)) as usize & ((1 << DIRECTION_BITS) - 1)
    }

    #[inline]
    fn bottleneck(self) -> usize {
        (self.0 & COUNT_MASK) as usize
    }
}

/// Every cell's [`Node`], reset for a new search by bumping the generation instead of
/// rewriting millions of entries.
#[derive(Debug, Default)]
pub(super) struct Nodes {
    nodes: Vec<Node>,
    pub(super) generation: u32,
}

impl Nodes {
    /// Makes every cell unset for a search over `cells` cells.
    fn reset(&mut self, cells: usize) {
        if self.nodes.len() != cells {
            self.nodes = vec![Node(0); cells];
            self.generation = 0;
        }
        // Two stamps per search (reached, settled); after 2²⁰ searches they run out: clear
        // once (8 MB written every million searches at most).
        self.generation = match self.generation.checked_add(2) {
            Some(next) if next < MAX_STAMP => next,
            _ => {
                self.nodes.iter_mut().for_each(|n| *n = Node(0));
                2
            }
        };
    }

    #[inline]
    pub(super) fn get(&self, cell: usize) -> Node {
        self.nodes[cell]
    }

    /// Records a node. A* may overwrite a settled one with a shorter way (the bucket queue
    /// does not order a bucket by f), which opens it again: it is then expanded once more.
    #[inline]
    fn set(&mut self, cell: usize, node: Node) {
        self.nodes[cell] = node;
    }
}

/// One search's working memory, kept between queries: on a 1001² map a fresh set was 12–21 MB
/// of allocation and zeroing per query.
#[derive(Debug, Default)]
pub(super) struct Scratch {
    pub(super) nodes: Nodes,
    /// A*'s open list (see [`BucketQueue`]). On the 19-wall maze of `scripts/vs-python.sh`
    /// (every cell settled) the search took 150–180 ms with a binary heap of (f, −h, cell),
    /// 95–117 ms with a radix heap keyed by f's bits (a quarter of it redistributing entries),
    /// and 65–75 ms with this.
    open: BucketQueue,
    /// The widest path's open list: (width, −distance to goal, cell), largest first.
    widest_heap: BinaryHeap<(OrdF64, Reverse<OrdF64>, usize)>,
    /// Lazy Theta*'s state, allocated by the first any-angle query.
    pub(super) theta: super::any_angle::ThetaScratch,
    /// Jump point search's state, allocated by the first indexed query.
    pub(super) jump: super::jump::JumpScratch,
}

/// Scratch sets kept for reuse; beyond that a search allocates its own and drops it. Each part
/// is allocated by the first search that needs it: A* and the widest path 8 B per cell of the
/// largest map queried (32 MB for four at the grid limit of 1001² cells), any-angle queries
/// 12.25 B more, jump point search 4 × 8 B per 64 × 64 block of cells (0.5 MB) and its jump
/// points and open list as they grew (a few thousand entries on the paper floor; at most one a
/// cell on a maze), kept with the set.
const POOLED_SCRATCH: usize = 4;
static SCRATCH_POOL: Mutex<Vec<Scratch>> = Mutex::new(Vec::new());

/// Runs `search` with a scratch set from the pool; each search resets the parts it uses (A*'s
/// [`Nodes`] by [`CellGraph::a_star`], which any-angle queries run first).
pub(super) fn with_scratch<R>(search: impl FnOnce(&mut Scratch) -> R) -> R {
    let pooled = SCRATCH_POOL
        .lock()
        .map(|mut pool| pool.pop())
        .ok()
        .flatten();
    let mut scratch = pooled.unwrap_or_default();
    let result = search(&mut scratch);
    if let Ok(mut pool) = SCRATCH_POOL.lock()
        && pool.len() < POOLED_SCRATCH
    {
        pool.push(scratch);
    }
    result
}

/// An f64 with a total order, for the priority queues (values are never NaN there).
#[derive(Debug, Clone, Copy, PartialEq)]
struct OrdF64(f64);
impl Eq for OrdF64 {}
impl PartialOrd for OrdF64 {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for OrdF64 {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn grid(nx: usize, ny: usize) -> Grid {
        Grid {
            nx,
            ny,
            x_min: 0.0,
            y_min: 0.0,
            resolution_m: 0.5,
        }
    }

    /// Bellman–Ford style relaxation over every cell until nothing changes: the brute force.
    fn brute_force_distance(
        g: &CellGraph,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Option<f64> {
        if !g.is_feasible(start, threshold) || !g.is_feasible(goal, threshold) {
            return None;
        }
        let mut dist = vec![f64::INFINITY; g.values.len()];
        dist[start] = 0.0;
        loop {
            let mut changed = false;
            for c in 0..g.values.len() {
                if !dist[c].is_finite() {
                    continue;
                }
                g.for_each_neighbour(c, |n, _, d| {
                    let len = NEIGHBOURS[d].2;
                    if g.is_feasible(n, threshold) && dist[c] + len < dist[n] - 1e-12 {
                        dist[n] = dist[c] + len;
                        changed = true;
                    }
                });
            }
            if !changed {
                break;
            }
        }
        dist[goal]
            .is_finite()
            .then(|| dist[goal] * g.grid.resolution_m)
    }

    fn arb_map() -> impl Strategy<Value = (usize, usize, Vec<f64>, Vec<bool>, usize, usize)> {
        (2usize..9, 2usize..9).prop_flat_map(|(nx, ny)| {
            let n = nx * ny;
            (
                Just(nx),
                Just(ny),
                proptest::collection::vec(0.0f64..10.0, n),
                proptest::collection::vec(proptest::bool::weighted(0.15), n),
                0..n,
                0..n,
            )
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        #[test]
        fn astar_equals_brute_force((nx, ny, mut values, occupied, s, t) in arb_map(), threshold in 0.0f64..8.0) {
            for (v, o) in values.iter_mut().zip(&occupied) { if *o { *v = f64::NAN; } }
            let gr = grid(nx, ny);
            let g = CellGraph { grid: &gr, values: &values, occupied: &occupied };
            let expected = brute_force_distance(&g, s, t, threshold);
            match g.a_star_path(s, t, threshold) {
                Ok(p) => {
                    let d = expected.expect("A* found a path the brute force did not");
                    prop_assert!((p.distance_m - d).abs() < 1e-9, "A* {} vs brute force {}", p.distance_m, d);
                    // The path itself is valid: feasible cells, adjacent steps summing to its length.
                    let mut len = 0.0;
                    for w in p.cells.windows(2) {
                        let mut step = None;
                        g.for_each_neighbour(w[0], |n, _, d| if n == w[1] { step = Some(NEIGHBOURS[d].2) });
                        len += step.expect("consecutive waypoints are neighbours");
                    }
                    prop_assert!(p.cells.iter().all(|&c| g.is_feasible(c, threshold)));
                    prop_assert!((len * gr.resolution_m - p.distance_m).abs() < 1e-9);
                }
                Err(_) => prop_assert!(expected.is_none()),
            }
        }

        #[test]
        fn widest_path_equals_bisection_with_dijkstra((nx, ny, mut values, occupied, s, t) in arb_map()) {
            for (v, o) in values.iter_mut().zip(&occupied) { if *o { *v = f64::NAN; } }
            let gr = grid(nx, ny);
            let g = CellGraph { grid: &gr, values: &values, occupied: &occupied };
            let widest = g.widest_path_threshold(s, t);
            // The answer is one of the cell values; bisect over the sorted distinct values with
            // the shortest-path planner as the feasibility oracle.
            let mut candidates: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
            candidates.sort_by(f64::total_cmp);
            candidates.dedup();
            let feasible = |gamma: f64| g.a_star_path(s, t, gamma).is_ok();
            let bisected = if candidates.is_empty() || !feasible(candidates[0]) { None } else {
                let (mut lo, mut hi) = (0usize, candidates.len()); // feasible(lo), !feasible(hi)
                while hi - lo > 1 {
                    let mid = (lo + hi) / 2;
                    if feasible(candidates[mid]) { lo = mid } else { hi = mid }
                }
                Some(candidates[lo])
            };
            prop_assert_eq!(widest, bisected);
        }

        /// The index answers every pair as the search does (ties, occupied corners, NaN cells,
        /// disconnected parts and start = goal included).
        #[test]
        fn bottleneck_index_equals_widest_search((nx, ny, mut values, occupied, _s, _t) in arb_map(), ties in any::<bool>()) {
            for (v, o) in values.iter_mut().zip(&occupied) {
                if *o { *v = f64::NAN; } else if ties { *v = v.floor(); }
            }
            let gr = grid(nx, ny);
            let g = CellGraph { grid: &gr, values: &values, occupied: &occupied };
            let index = super::super::Bottlenecks::new(&g);
            for s in 0..values.len() {
                for t in 0..values.len() {
                    prop_assert_eq!(index.widest_path_threshold(&values, s, t), g.widest_path_threshold(s, t), "{} -> {}", s, t);
                }
            }
        }
    }

    #[test]
    fn start_equal_to_goal_is_a_zero_length_path() {
        let gr = grid(3, 3);
        let values = vec![1.0; 9];
        let occupied = vec![false; 9];
        let g = CellGraph {
            grid: &gr,
            values: &values,
            occupied: &occupied,
        };
        let p = g.a_star_path(4, 4, 0.5).unwrap();
        assert_eq!(
            p,
            Path {
                cells: vec![4],
                distance_m: 0.0
            }
        );
    }

    #[test]
    fn reasons_are_reported_in_order() {
        let gr = grid(3, 1);
        let values = vec![1.0, f64::NAN, 0.2];
        let occupied = vec![false, true, false];
        let g = CellGraph {
            grid: &gr,
            values: &values,
            occupied: &occupied,
        };
        assert_eq!(g.a_star_path(1, 0, 0.0), Err(Infeasible::StartOccupied));
        assert_eq!(g.a_star_path(0, 1, 0.0), Err(Infeasible::GoalOccupied));
        assert_eq!(
            g.a_star_path(2, 0, 0.5),
            Err(Infeasible::StartBelowThreshold)
        );
        assert_eq!(
            g.a_star_path(0, 2, 0.5),
            Err(Infeasible::GoalBelowThreshold)
        );
        assert_eq!(g.a_star_path(0, 2, 0.1), Err(Infeasible::Disconnected));
    }

    #[test]
    fn diagonals_do_not_cut_occupied_corners() {
        // 2×2: (0,0) and (1,1) free, the other two occupied.
        let gr = grid(2, 2);
        let occupied = vec![false, true, true, false];
        let values = vec![1.0, f64::NAN, f64::NAN, 1.0];
        let g = CellGraph {
            grid: &gr,
            values: &values,
            occupied: &occupied,
        };
        assert_eq!(g.a_star_path(0, 3, 0.0), Err(Infeasible::Disconnected));
        // Below-threshold corners may be cut.
        let occupied = vec![false; 4];
        let values = vec![1.0, 0.0, 0.0, 1.0];
        let g = CellGraph {
            grid: &gr,
            values: &values,
            occupied: &occupied,
        };
        let p = g.a_star_path(0, 3, 0.5).unwrap();
        assert!((p.distance_m - 0.5 * std::f64::consts::SQRT_2).abs() < 1e-12);
    }
}
