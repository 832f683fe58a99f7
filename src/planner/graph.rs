//! The feasible map as a graph, and the searches on it (docs/model.md §6).
//!
//! The feasible map Π (paper eq. 14) marks the free cells whose value meets the threshold; the
//! graph joins each feasible cell to its feasible 8-neighbours with the Euclidean distance between
//! centres as weight (paper eqs. 15–16). The shortest path is found by A* with the octile
//! heuristic, which is admissible and consistent on this graph, so it returns Dijkstra's distance.
//!
//! One choice beyond the paper: a diagonal step may not cut the corner of an *occupied* cell (both
//! orthogonal neighbours must be free), because the segment between the two centres would graze
//! an obstacle. Cells that are merely below the threshold may be cut, as in the paper's Fig. 3.
//!
//! Beyond the paper, [`CellGraph::widest_path_threshold`] returns the largest threshold for which
//! any path exists (a bottleneck path: one Dijkstra-like pass maximising the minimum value along
//! the path).

use crate::scenario::Grid;
use serde::Serialize;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::Mutex;

/// Why no path exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Infeasible {
    StartOccupied,
    GoalOccupied,
    StartBelowThreshold,
    GoalBelowThreshold,
    Disconnected,
}

/// A shortest path: the visited cells (flat indices, start first) and its length in metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Path {
    pub cells: Vec<usize>,
    pub distance_m: f64,
}

/// The 8 neighbour offsets (di, dj) with their length in units of Δ.
const NEIGHBOURS: [(isize, isize, f64); 8] = [
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
    pub grid: &'a Grid,
    pub values: &'a [f64],
    pub occupied: &'a [bool],
}

impl<'a> CellGraph<'a> {
    /// Calls `visit(neighbour, step_length_in_cells)` for every neighbour of `cell` that is free
    /// and reachable without cutting an occupied corner.
    #[inline]
    fn for_each_neighbour(&self, cell: usize, mut visit: impl FnMut(usize, f64)) {
        let (i, j) = self.grid.cell_of(cell);
        let (nx, ny) = (self.grid.nx as isize, self.grid.ny as isize);
        for &(di, dj, len) in &NEIGHBOURS {
            let (a, b) = (i as isize + di, j as isize + dj);
            if a < 0 || b < 0 || a >= nx || b >= ny {
                continue;
            }
            let n = self.grid.index(a as usize, b as usize);
            if self.occupied[n] {
                continue;
            }
            if di != 0 && dj != 0 {
                let side1 = self.grid.index(a as usize, j);
                let side2 = self.grid.index(i, b as usize);
                if self.occupied[side1] || self.occupied[side2] {
                    continue;
                }
            }
            visit(n, len);
        }
    }

    /// Π_{i,j} of paper eq. 14.
    #[inline]
    pub fn is_feasible(&self, cell: usize, threshold: f64) -> bool {
        !self.occupied[cell] && self.values[cell] >= threshold
    }

    /// Shortest feasible path from `start` to `goal` (paper problem 13), or why there is none.
    pub fn shortest_path(
        &self,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Result<Path, Infeasible> {
        self.check_ends(start, goal, threshold)?;
        let heuristic = self.octile_to(goal);
        with_scratch(self.values.len(), |scratch| {
            let Scratch {
                dist, prev, heap, ..
            } = scratch;
            dist.set(start, 0.0);
            // Entries of equal f are taken farther-from-the-goal first (larger h): a rule that
            // does not depend on which end is the start. On the 1001² floor at −62 dB, ties by
            // cell index cost 16 ms one way and 27–30 ms the other; larger h first 14–18 ms and
            // 12–17 ms; smaller h first 27–35 ms both ways (interleaved runs, one session).
            heap.push(Reverse((
                OrdF64(heuristic(start)),
                OrdF64(-heuristic(start)),
                start,
            )));
            while let Some(Reverse((OrdF64(f), OrdF64(minus_h), cell))) = heap.pop() {
                let h = -minus_h;
                if cell == goal {
                    break;
                }
                let g = dist.get(cell);
                if f > g + h + 1e-9 {
                    continue; // stale entry
                }
                self.for_each_neighbour(cell, |n, len| {
                    if !self.is_feasible(n, threshold) {
                        return;
                    }
                    let candidate = g + len;
                    if candidate < dist.get(n) {
                        dist.set(n, candidate);
                        prev[n] = cell as u32;
                        let h = heuristic(n);
                        heap.push(Reverse((OrdF64(candidate + h), OrdF64(-h), n)));
                    }
                });
            }
            heap.clear();
            let length = dist.get(goal);
            if !length.is_finite() {
                return Err(Infeasible::Disconnected);
            }
            let mut path = vec![goal];
            while *path.last().unwrap() != start {
                path.push(prev[*path.last().unwrap()] as usize);
            }
            path.reverse();
            Ok(Path {
                cells: path,
                distance_m: length * self.grid.resolution_m,
            })
        })
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
        with_scratch(self.values.len(), |scratch| {
            // `dist` holds the widest width found so far, negated (its unset value is +∞).
            let Scratch {
                dist: narrowest,
                done,
                widest_heap: heap,
                ..
            } = scratch;
            let best = |narrowest: &Stamped<f64>, c: usize| -narrowest.get(c);
            narrowest.set(start, -value(start));
            // Among entries of equal width the one nearer the goal goes first: widths tie on
            // every cell above a narrow end, and breaking the tie by cell index made the search
            // cost 1 ms one way and 37 ms the other on the 1001² floor.
            heap.push((OrdF64(value(start)), Reverse(OrdF64(to_goal(start))), start));
            while let Some((OrdF64(b), _, cell)) = heap.pop() {
                if done.get(cell) {
                    continue;
                }
                done.set(cell, true);
                if cell == goal || best(narrowest, goal) >= ceiling {
                    break;
                }
                self.for_each_neighbour(cell, |n, _| {
                    let through = b.min(value(n));
                    if !done.get(n) && through > best(narrowest, n) {
                        narrowest.set(n, -through);
                        heap.push((OrdF64(through), Reverse(OrdF64(to_goal(n))), n));
                    }
                });
            }
            heap.clear();
            let width = best(narrowest, goal);
            width.is_finite().then_some(width)
        })
    }

    /// The octile distance to `goal` in units of Δ (the shortest 8-connected length on an
    /// empty grid, so an admissible and consistent A* heuristic), with the goal's coordinates
    /// worked out once: the searches call it for every neighbour they push.
    fn octile_to(&self, goal: usize) -> impl Fn(usize) -> f64 + '_ {
        let (gi, gj) = self.grid.cell_of(goal);
        move |c: usize| {
            let (i, j) = self.grid.cell_of(c);
            let (dx, dy) = (i.abs_diff(gi) as f64, j.abs_diff(gj) as f64);
            dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)
        }
    }

    fn check_ends(&self, start: usize, goal: usize, threshold: f64) -> Result<(), Infeasible> {
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

/// A per-cell array whose entries read as `unset` until written in the current search:
/// starting a search bumps the generation instead of refilling millions of entries.
#[derive(Debug)]
struct Stamped<T: Copy> {
    values: Vec<T>,
    stamps: Vec<u32>,
    generation: u32,
    unset: T,
}

impl<T: Copy> Stamped<T> {
    fn new(unset: T) -> Self {
        Stamped {
            values: Vec::new(),
            stamps: Vec::new(),
            generation: 0,
            unset,
        }
    }

    /// Makes every entry unset for a search over `cells` cells.
    fn reset(&mut self, cells: usize) {
        if self.values.len() != cells {
            self.values = vec![self.unset; cells];
            self.stamps = vec![0; cells];
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            // After 2³² searches the stamps wrap: clear them once.
            self.stamps.iter_mut().for_each(|s| *s = 0);
            self.generation = 1;
        }
    }

    #[inline]
    fn get(&self, cell: usize) -> T {
        if self.stamps[cell] == self.generation {
            self.values[cell]
        } else {
            self.unset
        }
    }

    #[inline]
    fn set(&mut self, cell: usize, value: T) {
        self.stamps[cell] = self.generation;
        self.values[cell] = value;
    }
}

/// One search's working memory, kept between queries: on a 1001² map a fresh set was 12–21 MB
/// of allocation and zeroing per query.
#[derive(Debug)]
struct Scratch {
    /// A*: g per cell; widest path: minus the best width. Unset reads +∞ (no width: −∞).
    dist: Stamped<f64>,
    /// Widest path: cells already settled.
    done: Stamped<bool>,
    /// A*: each cell's predecessor, valid where `dist` is set.
    prev: Vec<u32>,
    /// A*'s open list: (f, −h, cell), smallest f then largest h first.
    heap: BinaryHeap<Reverse<(OrdF64, OrdF64, usize)>>,
    /// The widest path's open list: (width, −distance to goal, cell), largest first.
    widest_heap: BinaryHeap<(OrdF64, Reverse<OrdF64>, usize)>,
}

/// Scratch sets kept for reuse: as many as searches usually run at once (the query pool's
/// workers); beyond that a search allocates its own and drops it. At most 4 × 21 B per cell of
/// the largest map queried stay allocated: 84 MB at the grid limit of 1001² cells.
const POOLED_SCRATCH: usize = 4;
static SCRATCH_POOL: Mutex<Vec<Scratch>> = Mutex::new(Vec::new());

/// Runs `search` with a scratch set sized and reset for `cells` cells.
fn with_scratch<R>(cells: usize, search: impl FnOnce(&mut Scratch) -> R) -> R {
    let pooled = SCRATCH_POOL
        .lock()
        .map(|mut pool| pool.pop())
        .ok()
        .flatten();
    let mut scratch = pooled.unwrap_or_else(|| Scratch {
        dist: Stamped::new(f64::INFINITY),
        done: Stamped::new(false),
        prev: Vec::new(),
        heap: BinaryHeap::new(),
        widest_heap: BinaryHeap::new(),
    });
    scratch.dist.reset(cells);
    scratch.done.reset(cells);
    if scratch.prev.len() != cells {
        scratch.prev = vec![u32::MAX; cells];
    }
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
                g.for_each_neighbour(c, |n, len| {
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
            match g.shortest_path(s, t, threshold) {
                Ok(p) => {
                    let d = expected.expect("A* found a path the brute force did not");
                    prop_assert!((p.distance_m - d).abs() < 1e-9, "A* {} vs brute force {}", p.distance_m, d);
                    // The path itself is valid: feasible cells, adjacent steps summing to its length.
                    let mut len = 0.0;
                    for w in p.cells.windows(2) {
                        let mut step = None;
                        g.for_each_neighbour(w[0], |n, l| if n == w[1] { step = Some(l) });
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
            let feasible = |gamma: f64| g.shortest_path(s, t, gamma).is_ok();
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
        let p = g.shortest_path(4, 4, 0.5).unwrap();
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
        assert_eq!(g.shortest_path(1, 0, 0.0), Err(Infeasible::StartOccupied));
        assert_eq!(g.shortest_path(0, 1, 0.0), Err(Infeasible::GoalOccupied));
        assert_eq!(
            g.shortest_path(2, 0, 0.5),
            Err(Infeasible::StartBelowThreshold)
        );
        assert_eq!(
            g.shortest_path(0, 2, 0.5),
            Err(Infeasible::GoalBelowThreshold)
        );
        assert_eq!(g.shortest_path(0, 2, 0.1), Err(Infeasible::Disconnected));
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
        assert_eq!(g.shortest_path(0, 3, 0.0), Err(Infeasible::Disconnected));
        // Below-threshold corners may be cut.
        let occupied = vec![false; 4];
        let values = vec![1.0, 0.0, 0.0, 1.0];
        let g = CellGraph {
            grid: &gr,
            values: &values,
            occupied: &occupied,
        };
        let p = g.shortest_path(0, 3, 0.5).unwrap();
        assert!((p.distance_m - 0.5 * std::f64::consts::SQRT_2).abs() < 1e-12);
    }
}
