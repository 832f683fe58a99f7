//! Any-angle paths (docs/model.md §6, "Any-angle paths"): straight segments between cell
//! centres instead of 8-connected steps, each segment allowed only where the robot may drive it.
//!
//! **Line of sight, exactly.** A segment between two cell centres has integer end points in
//! cell coordinates, so the cells it meets follow from integer comparisons alone
//! ([`segment_cells`]): it crosses the *interior* of a sequence of cells, and where it passes
//! exactly through a corner of the grid it also touches the two cells beside that corner. A
//! segment is allowed when every cell whose interior it crosses is free and meets the threshold,
//! and every cell it touches at a corner is free. This is the 8-connected graph's rule extended
//! to any angle: a diagonal step may cut the corner of a cell below the threshold but not of an
//! occupied one (whose obstacle may reach its corner under the conservative occupancy of §1).
//!
//! **The search** is Lazy Theta* (Nash, Koenig and Tovey, AAAI 2010): A* over the feasible
//! cells in which a reached cell takes its predecessor's parent as its own, assuming line of
//! sight, and checks that assumption once, when it is expanded; where it fails, the best
//! expanded neighbour becomes the parent, as in A*. Theta*-class searches are not guaranteed to
//! find the shortest any-angle path, nor one shorter than the 8-connected path, so the planner
//! also pulls the 8-connected path taut (from each vertex the run of later cells in sight is
//! followed to its last one, the next vertex) and answers the shorter of the two: never longer
//! than the grid path.
//!
//! **Its heuristic is the grid search's.** The 8-connected search runs first anyway (it decides
//! whether a path exists, and bounds the answer's length); run from the goal, it leaves every
//! cell it reached with its 8-connected distance to the goal, which knows the obstacles and the
//! cells below the threshold where the Euclidean distance does not. Lazy Theta* takes it as its
//! heuristic and searches only those cells. That distance exceeds the any-angle one by at most
//! 8.2 % in the open (the octile detour along some headings), which would bias the search
//! towards the headings where it is least; so the heuristic is the Euclidean distance plus only
//! the detour the obstacles force (the grid distance less the octile one). Weighted
//! ([`HEURISTIC_WEIGHT`]), the search goes round obstacles instead of flooding the bays in
//! front of them: on the paper floor and the warehouse it expands 3–40× fewer cells than the
//! Euclidean heuristic weighted by 1.5 did, for paths 0.2–1.8 % shorter (docs/performance.md).
//! Its lines of sight are budgeted ([`LOS_BUDGET_PER_CELL`]) so that no floor makes it cost
//! more than a bounded multiple of the map's size.

use super::graph::{CellGraph, Infeasible, Scratch, with_scratch};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// Visits the cells a segment between the centres of cells `a` and `b` (each (i, j)) meets, in
/// order from `a`: `visit(i, j, interior)` with `interior` true for a cell whose interior the
/// segment crosses and false for one it only touches at a corner. The entry point of each
/// interior cell is passed as the fraction `t` of the segment at which it is entered (0 for `a`).
/// Stops early, returning false, when `visit` does.
pub(crate) fn segment_cells(
    a: (usize, usize),
    b: (usize, usize),
    mut visit: impl FnMut(usize, usize, bool, f64) -> bool,
) -> bool {
    let (x0, y0) = (a.0 as i64, a.1 as i64);
    let (x1, y1) = (b.0 as i64, b.1 as i64);
    let (dx, dy) = (x1 - x0, y1 - y0);
    let (sx, sy) = (dx.signum(), dy.signum());
    let (adx, ady) = (dx.abs(), dy.abs());
    let (mut x, mut y) = (x0, y0);
    if !visit(x as usize, y as usize, true, 0.0) {
        return false;
    }
    // Steps taken along x and y; the next boundary along x is crossed at
    // t = (2·nx + 1) / (2·|dx|), along y at (2·ny + 1) / (2·|dy|).
    let (mut nx, mut ny) = (0i64, 0i64);
    while (x, y) != (x1, y1) {
        // Compare the two crossing fractions without dividing: (2nx+1)·|dy| vs (2ny+1)·|dx|.
        let (along_x, along_y) = ((2 * nx + 1) * ady, (2 * ny + 1) * adx);
        let step = if ady == 0 || (adx != 0 && along_x < along_y) {
            (true, false)
        } else if adx == 0 || along_y < along_x {
            (false, true)
        } else {
            (true, true)
        };
        let t = if step.0 {
            (2 * nx + 1) as f64 / (2 * adx) as f64
        } else {
            (2 * ny + 1) as f64 / (2 * ady) as f64
        };
        if step.0 && step.1 {
            // Through a corner: the two cells beside it are touched there, no more.
            if !visit((x + sx) as usize, y as usize, false, t)
                || !visit(x as usize, (y + sy) as usize, false, t)
            {
                return false;
            }
        }
        if step.0 {
            x += sx;
            nx += 1;
        }
        if step.1 {
            y += sy;
            ny += 1;
        }
        if !visit(x as usize, y as usize, true, t) {
            return false;
        }
    }
    true
}

impl CellGraph<'_> {
    /// The shortest any-angle path this planner finds from `start` to `goal` at `threshold`
    /// (see the module's notes): its vertices (flat indices of cell centres, start first) and
    /// length in metres, never longer than [`CellGraph::shortest_path`]'s.
    pub fn any_angle_path(
        &self,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Result<AnyAnglePath, Infeasible> {
        self.check_ends(start, goal, threshold)?;
        with_scratch(|scratch| {
            // From the goal: every cell the grid search reaches then knows its 8-connected
            // distance to the goal, Lazy Theta*'s heuristic. Its path comes start first.
            let (grid_cells, _) = self.a_star(scratch, goal, start, threshold)?;
            scratch.theta.passable.fill(self, threshold);
            let taut = pull_taut(&scratch.theta.passable, self.grid, &grid_cells);
            let searched = self.lazy_theta(scratch, start, goal);
            let searched = pull_taut(&scratch.theta.passable, self.grid, &searched);
            let (taut_len, searched_len) = (self.length(&taut), self.length(&searched));
            let vertices = if !searched.is_empty() && searched_len < taut_len {
                searched
            } else {
                taut
            };
            let distance_m = self.length(&vertices) * self.grid.resolution_m;
            Ok(AnyAnglePath {
                vertices,
                distance_m,
            })
        })
    }

    /// The polyline's length in cells.
    fn length(&self, vertices: &[usize]) -> f64 {
        vertices
            .windows(2)
            .map(|w| {
                let (a, b) = (self.grid.cell_of(w[0]), self.grid.cell_of(w[1]));
                (a.0.abs_diff(b.0) as f64).hypot(a.1.abs_diff(b.1) as f64)
            })
            .sum()
    }

    /// Lazy Theta* from `start` to `goal` over the cells the grid search (run from the goal,
    /// in `scratch`) reached, its distances to the goal as heuristic: the vertices found
    /// (start first), or none if the line-of-sight budget ran out.
    fn lazy_theta(&self, scratch: &mut Scratch, start: usize, goal: usize) -> Vec<usize> {
        let cells = self.values.len();
        let ny = self.grid.ny;
        let Scratch { nodes, theta, .. } = scratch;
        let ThetaScratch {
            passable,
            state,
            open,
        } = theta;
        state.reset(cells);
        open.clear();
        let generation = nodes.generation;
        let (gi, gj) = self.grid.cell_of(goal);
        let norm = |di: f64, dj: f64| (di * di + dj * dj).sqrt();
        // Where the grid search reached the cell: the Euclidean distance to the goal plus the
        // detour the grid distance makes beyond the octile one (obstacles, cells below the
        // threshold); the cells it did not reach stay out.
        let h = |c: usize| {
            let node = nodes.get(c);
            node.is_reached(generation).then(|| {
                let (i, j) = (c / ny, c % ny);
                let (dx, dy) = (i.abs_diff(gi) as f64, j.abs_diff(gj) as f64);
                let octile = dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy);
                HEURISTIC_WEIGHT * (norm(dx, dy) + (node.length() - octile).max(0.0))
            })
        };
        state.set(start, 0.0, start);
        open.push((Reverse(Key(h(start).unwrap_or(0.0))), start as u32));
        // Cell tests spent on lines of sight: past the budget the search stops and the caller
        // keeps the grid path pulled taut, so a query's cost stays a bounded multiple of the
        // map's size whatever the floor.
        let mut budget = LOS_BUDGET_PER_CELL * cells;
        while let Some((Reverse(Key(f)), s)) = open.pop() {
            let s = s as usize;
            let here = (s / ny, s % ny);
            let h_here = h(s).unwrap_or(0.0);
            if state.is_closed(s) || f > state.g(s) + h_here + 1e-9 {
                continue;
            }
            let p = state.parent(s);
            if p != s {
                let (seen, cost) = passable.line_of_sight(self.grid.cell_of(p), here);
                budget = budget.saturating_sub(cost);
                if budget == 0 {
                    return Vec::new();
                }
                if !seen {
                    // The assumed segment is blocked: the best expanded neighbour is the parent.
                    let (mut best, mut best_g) = (p, f64::INFINITY);
                    self.for_each_neighbour(s, |n, (a, b), _| {
                        if !state.is_closed(n) {
                            return;
                        }
                        let through =
                            state.g(n) + norm(a as f64 - here.0 as f64, b as f64 - here.1 as f64);
                        if through < best_g {
                            (best, best_g) = (n, through);
                        }
                    });
                    state.set(s, best_g, best);
                }
            }
            state.close(s);
            if s == goal {
                break;
            }
            let origin = state.parent(s);
            let (oi, oj) = (origin / ny, origin % ny);
            let g_origin = state.g(origin);
            self.for_each_neighbour(s, |n, at, _| {
                if state.is_closed(n) || !passable.feasible(n) {
                    return;
                }
                let Some(h_n) = h(n) else {
                    return;
                };
                // Rounded as the state keeps it, so the stale test below matches this entry.
                let candidate = f64::from(
                    (g_origin + norm(at.0 as f64 - oi as f64, at.1 as f64 - oj as f64)) as f32,
                );
                if candidate < state.g(n) {
                    state.set(n, candidate, origin);
                    open.push((Reverse(Key(candidate + h_n)), n as u32));
                }
            });
        }
        if !state.is_closed(goal) {
            return Vec::new();
        }
        let mut vertices = vec![goal];
        let mut c = goal;
        while c != start {
            c = state.parent(c);
            vertices.push(c);
        }
        vertices.reverse();
        vertices
    }
}

/// A polyline through `cells` pulled taut: from each vertex, the run of later cells in sight
/// is followed to its last one, which becomes the next vertex. Each shortcut replaces a
/// stretch by a straight segment, so the result is never longer.
fn pull_taut(passable: &Passable, grid: &crate::scenario::Grid, cells: &[usize]) -> Vec<usize> {
    let Some(&first) = cells.first() else {
        return Vec::new();
    };
    let in_sight = |a: usize, b: usize| passable.line_of_sight(grid.cell_of(a), grid.cell_of(b)).0;
    let mut vertices = vec![first];
    let mut anchor = 0;
    let mut k = 1;
    while k < cells.len() {
        // Extend while the next cell is in sight of the anchor; the last one in sight
        // becomes a vertex (two neighbours in the path are always in sight of each other).
        if k + 1 < cells.len() && in_sight(cells[anchor], cells[k + 1]) {
            k += 1;
            continue;
        }
        vertices.push(cells[k]);
        anchor = k;
        k += 1;
    }
    vertices
}

/// What an any-angle query keeps between queries (in the planner's scratch, see
/// `graph::with_scratch`): 12.25 B a cell, allocated by the first query on a grid of its size.
#[derive(Debug, Default)]
pub(super) struct ThetaScratch {
    passable: Passable,
    state: ThetaState,
    open: BinaryHeap<(Reverse<Key>, u32)>,
}

/// Lazy Theta*'s per-cell state, reset for a new search by bumping a generation (as the grid
/// search's nodes are) instead of rewriting 12 MB on a 1001² grid.
#[derive(Debug, Default)]
struct ThetaState {
    /// Per cell: the best length found from the start (cells), its parent, and the search
    /// that wrote it (`generation` when reached, one more once expanded; older reads as unset).
    cells: Vec<(f32, u32, u32)>,
    generation: u32,
}

impl ThetaState {
    fn reset(&mut self, cells: usize) {
        if self.cells.len() != cells {
            self.cells = vec![(0.0, 0, 0); cells];
            self.generation = 0;
        }
        self.generation = match self.generation.checked_add(2) {
            Some(next) => next,
            None => {
                self.cells.iter_mut().for_each(|c| c.2 = 0);
                2
            }
        };
    }

    /// The best length found to `cell` (cells), infinite before it is reached. Kept as f32:
    /// it only orders the search (the answer's lengths are recomputed in f64), and 2⁻²⁴
    /// relative is far below a cell at any grid size.
    #[inline]
    fn g(&self, cell: usize) -> f64 {
        let (g, _, stamp) = self.cells[cell];
        if stamp >= self.generation {
            f64::from(g)
        } else {
            f64::INFINITY
        }
    }

    #[inline]
    fn parent(&self, cell: usize) -> usize {
        self.cells[cell].1 as usize
    }

    #[inline]
    fn is_closed(&self, cell: usize) -> bool {
        self.cells[cell].2 == self.generation + 1
    }

    #[inline]
    fn set(&mut self, cell: usize, g: f64, parent: usize) {
        let stamp = self.cells[cell].2.max(self.generation);
        self.cells[cell] = (g as f32, parent as u32, stamp);
    }

    #[inline]
    fn close(&mut self, cell: usize) {
        self.cells[cell].2 = self.generation + 1;
    }
}

/// The feasible and the free cells as bitsets (2 bits a cell: 250 kB for 1001² cells, so the
/// lines of sight Lazy Theta* walks stay in cache instead of reading a value and a flag per cell
/// from 9 MB).
#[derive(Debug, Default)]
struct Passable {
    ny: usize,
    feasible: Vec<u64>,
    free: Vec<u64>,
}

impl Passable {
    /// Fills the bitsets for `graph` at `threshold`, reusing their memory.
    fn fill(&mut self, graph: &CellGraph, threshold: f64) {
        let words = graph.values.len().div_ceil(64);
        self.ny = graph.grid.ny;
        self.feasible.resize(words, 0);
        self.free.resize(words, 0);
        // 64 cells a word, each bit set without a branch, so the loop vectorises.
        let chunks = graph.values.chunks(64).zip(graph.occupied.chunks(64));
        for ((feasible, free), (values, occupied)) in
            self.feasible.iter_mut().zip(&mut self.free).zip(chunks)
        {
            let (mut f, mut r) = (0u64, 0u64);
            for (k, (&v, &o)) in values.iter().zip(occupied).enumerate() {
                let is_free = u64::from(!o);
                r |= is_free << k;
                f |= (is_free & u64::from(v >= threshold)) << k;
            }
            (*feasible, *free) = (f, r);
        }
    }

    #[inline]
    fn feasible(&self, c: usize) -> bool {
        self.feasible[c / 64] >> (c % 64) & 1 == 1
    }
    /// [`CellGraph::line_of_sight`] on the bitsets, and the cells it tested: the walk of
    /// [`segment_cells`] without the entry fractions, which cost a division a step.
    fn line_of_sight(&self, a: (usize, usize), b: (usize, usize)) -> (bool, usize) {
        let bit = |set: &[u64], i: i64, j: i64| {
            let c = i as usize * self.ny + j as usize;
            set[c / 64] >> (c % 64) & 1 == 1
        };
        let (x1, y1) = (b.0 as i64, b.1 as i64);
        let (mut x, mut y) = (a.0 as i64, a.1 as i64);
        let (sx, sy) = ((x1 - x).signum(), (y1 - y).signum());
        let (adx, ady) = ((x1 - x).abs(), (y1 - y).abs());
        // The next side crossed along x comes at (2nx + 1)/(2|dx|) of the segment, along y at
        // (2ny + 1)/(2|dy|); compared as along_x = (2nx + 1)|dy| against along_y = (2ny + 1)|dx|,
        // each grown by 2|dy| (2|dx|) per step. A zero |dy| keeps along_x at 0: only x steps.
        let (mut along_x, mut along_y) = (ady, adx);
        let mut tested = 1;
        if !bit(&self.feasible, x, y) {
            return (false, tested);
        }
        while (x, y) != (x1, y1) {
            if along_x < along_y {
                x += sx;
                along_x += 2 * ady;
            } else if along_y < along_x {
                y += sy;
                along_y += 2 * adx;
            } else {
                tested += 2;
                if !bit(&self.free, x + sx, y) || !bit(&self.free, x, y + sy) {
                    return (false, tested);
                }
                (x, y) = (x + sx, y + sy);
                (along_x, along_y) = (along_x + 2 * ady, along_y + 2 * adx);
            }
            tested += 1;
            if !bit(&self.feasible, x, y) {
                return (false, tested);
            }
        }
        (true, tested)
    }
}

/// Cell tests Lazy Theta* may spend on lines of sight, per cell of the map. On the 1001² paper
/// floor a search spends 4–9 per cell; a floor that would need more (a maze of long sight
/// lines) keeps the grid path pulled taut instead of taking seconds.
const LOS_BUDGET_PER_CELL: usize = 64;

/// The weight of Lazy Theta*'s heuristic. Above 1 the search expands fewer cells (and tests
/// fewer lines of sight) for a path at most this factor longer than the best it would find
/// unweighted. Measured (`cargo bench --bench maps -- any_angle`, docs/performance.md) on the
/// paper floor at 2 cm and the warehouse at 5 cm, two thresholds each, weights 1, 1.1, 1.2 and
/// 1.35 found the same four paths. Unweighted, the search expanded 14 000–89 000 cells and
/// tested 2–15 million cells for sight (2.9–4.8× the grid search's time); at 1.2, 1 000–5 500
/// and 0.2–1.2 million (0.9–2.1×).
const HEURISTIC_WEIGHT: f64 = 1.2;

/// An any-angle path: straight segments between the centres of its vertices.
#[derive(Debug, Clone, PartialEq)]
pub struct AnyAnglePath {
    /// Flat indices of the vertices' cells, start first and goal last.
    pub vertices: Vec<usize>,
    /// Length (m).
    pub distance_m: f64,
}

/// An f64 key with a total order (never NaN here).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Key(f64);
impl Eq for Key {}
impl PartialOrd for Key {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Key {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Grid;
    use proptest::prelude::*;

    /// Whether the segment between the centres of cells `a` and `b` (flat indices) may be
    /// driven at `threshold`, by the exact traversal: every cell whose interior it crosses
    /// free and at least `threshold`, every cell it touches at a corner free.
    fn exact_line_of_sight(g: &CellGraph, a: usize, b: usize, threshold: f64) -> bool {
        let ny = g.grid.ny;
        segment_cells(g.grid.cell_of(a), g.grid.cell_of(b), |i, j, interior, _| {
            let c = i * ny + j;
            if interior {
                g.is_feasible(c, threshold)
            } else {
                !g.occupied[c]
            }
        })
    }

    /// How a segment between the centres of cells `a` and `b` meets cell (i, j), by exact
    /// rational arithmetic on the parameter t ∈ [0, 1] of the segment, independent of the
    /// traversal: (crosses its open interior, meets its closed square).
    fn meets(a: (usize, usize), b: (usize, usize), (i, j): (usize, usize)) -> (bool, bool) {
        // In doubled coordinates the centres are even and the cell's sides odd: the cell spans
        // [2i − 1, 2i + 1] along x. A bound is a fraction num/den of t with den > 0.
        type Fraction = (i64, i64);
        let axis = |p0: usize, p1: usize, c: usize| -> Option<(Fraction, Fraction)> {
            let (p0, d, c) = (2 * p0 as i64, 2 * (p1 as i64 - p0 as i64), 2 * c as i64);
            if d == 0 {
                // Constant along this axis: inside the open side only if strictly between.
                return ((p0 - c).abs() < 1).then_some(((-1, 1), (2, 1)));
            }
            let (lo, hi) = ((c - 1 - p0, d), (c + 1 - p0, d));
            let norm = |(n, den): Fraction| if den < 0 { (-n, -den) } else { (n, den) };
            let (lo, hi) = (norm(lo), norm(hi));
            Some(if lo.0 * hi.1 <= hi.0 * lo.1 {
                (lo, hi)
            } else {
                (hi, lo)
            })
        };
        let lt = |x: Fraction, y: Fraction| {
            (x.0 as i128) * (y.1 as i128) < (y.0 as i128) * (x.1 as i128)
        };
        let le = |x: Fraction, y: Fraction| {
            (x.0 as i128) * (y.1 as i128) <= (y.0 as i128) * (x.1 as i128)
        };
        let max = |x: Fraction, y: Fraction| if lt(x, y) { y } else { x };
        let min = |x: Fraction, y: Fraction| if lt(x, y) { x } else { y };
        // A constant coordinate exactly on a side touches the closed square for every t.
        let closed_axis = |p0: usize, p1: usize, c: usize| -> Option<(Fraction, Fraction)> {
            if p0 == p1 {
                return (p0.abs_diff(c) == 0).then_some(((-1, 1), (2, 1)));
            }
            axis(p0, p1, c)
        };
        let interior = match (axis(a.0, b.0, i), axis(a.1, b.1, j)) {
            (Some((xl, xh)), Some((yl, yh))) => {
                let (lo, hi) = (max(xl, yl), min(xh, yh));
                lt(lo, hi) && lt(lo, (1, 1)) && lt((0, 1), hi)
            }
            _ => false,
        };
        let closed = match (closed_axis(a.0, b.0, i), closed_axis(a.1, b.1, j)) {
            (Some((xl, xh)), Some((yl, yh))) => {
                let (lo, hi) = (max(xl, yl), min(xh, yh));
                le(lo, hi) && le(lo, (1, 1)) && le((0, 1), hi)
            }
            _ => false,
        };
        (interior, closed)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(500))]

        /// The traversal visits exactly the cells whose interior the segment crosses (in
        /// order of entry, each once) and, flagged, exactly those it meets only at a corner.
        #[test]
        fn segment_cells_are_exact(a in (1usize..11, 1usize..11), b in (1usize..11, 1usize..11)) {
            let mut interior = Vec::new();
            let mut corner = Vec::new();
            let mut last_t = -1.0;
            segment_cells(a, b, |i, j, inside, t| {
                if inside {
                    assert!(t >= last_t, "entries in order");
                    last_t = t;
                    interior.push((i, j));
                } else {
                    corner.push((i, j));
                }
                true
            });
            for i in 0..12 {
                for j in 0..12 {
                    let (crosses, touches) = meets(a, b, (i, j));
                    let seen_inside = interior.iter().filter(|&&c| c == (i, j)).count();
                    let seen_corner = corner.iter().filter(|&&c| c == (i, j)).count();
                    prop_assert_eq!(seen_inside, usize::from(crosses), "{:?}→{:?} cell {:?}", a, b, (i, j));
                    prop_assert_eq!(seen_corner, usize::from(touches && !crosses), "{:?}→{:?} cell {:?}", a, b, (i, j));
                }
            }
            prop_assert_eq!(interior.first(), Some(&a));
            prop_assert_eq!(interior.last(), Some(&b));
        }

        /// On random maps the any-angle path exists exactly when the grid path does, is never
        /// longer, and every segment crosses only feasible cells and touches only free ones,
        /// checked cell by cell by exact arithmetic.
        #[test]
        fn any_angle_paths_are_valid_and_never_longer(
            (nx, ny) in (2usize..14, 2usize..14),
            seed in any::<u64>(),
            threshold in 0.0f64..8.0,
            ends in (any::<u32>(), any::<u32>()),
        ) {
            use rand::{RngExt, SeedableRng};
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let n = nx * ny;
            let occupied: Vec<bool> = (0..n).map(|_| rng.random::<f64>() < 0.12).collect();
            let values: Vec<f64> = (0..n)
                .map(|c| if occupied[c] { f64::NAN } else { rng.random_range(0.0..10.0) })
                .collect();
            let grid = Grid { nx, ny, x_min: 0.0, y_min: 0.0, resolution_m: 0.5 };
            let g = CellGraph { grid: &grid, values: &values, occupied: &occupied };
            let (s, t) = (ends.0 as usize % n, ends.1 as usize % n);
            match (g.shortest_path(s, t, threshold), g.any_angle_path(s, t, threshold)) {
                (Ok(grid_path), Ok(path)) => {
                    prop_assert!(path.distance_m <= grid_path.distance_m + 1e-9,
                        "{} > {}", path.distance_m, grid_path.distance_m);
                    prop_assert_eq!(path.vertices.first(), Some(&s));
                    prop_assert_eq!(path.vertices.last(), Some(&t));
                    for pair in path.vertices.windows(2) {
                        let (a, b) = (grid.cell_of(pair[0]), grid.cell_of(pair[1]));
                        for (c, &occupied_c) in occupied.iter().enumerate() {
                            let (crosses, touches) = meets(a, b, grid.cell_of(c));
                            if crosses {
                                prop_assert!(g.is_feasible(c, threshold), "{:?}→{:?} crosses {:?}", a, b, grid.cell_of(c));
                            }
                            if touches {
                                prop_assert!(!occupied_c, "{:?}→{:?} touches occupied {:?}", a, b, grid.cell_of(c));
                            }
                        }
                    }
                }
                (Err(e), Err(f)) => prop_assert_eq!(e, f),
                (a, b) => prop_assert!(false, "grid {:?} vs any-angle {:?}", a.is_ok(), b.is_ok()),
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// The bitset walk Lazy Theta* uses agrees with the exact traversal on every segment.
        #[test]
        fn bitset_lines_of_sight_agree(
            (nx, ny) in (2usize..12, 2usize..12),
            seed in any::<u64>(),
            threshold in 0.0f64..10.0,
            ends in (any::<u32>(), any::<u32>()),
        ) {
            use rand::{RngExt, SeedableRng};
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
            let n = nx * ny;
            let occupied: Vec<bool> = (0..n).map(|_| rng.random::<f64>() < 0.1).collect();
            let values: Vec<f64> = (0..n).map(|_| rng.random_range(0.0..10.0)).collect();
            let grid = Grid { nx, ny, x_min: 0.0, y_min: 0.0, resolution_m: 0.5 };
            let g = CellGraph { grid: &grid, values: &values, occupied: &occupied };
            let (a, b) = (ends.0 as usize % n, ends.1 as usize % n);
            let mut bits = Passable::default();
            bits.fill(&g, threshold);
            let (seen, _) = bits.line_of_sight(grid.cell_of(a), grid.cell_of(b));
            prop_assert_eq!(seen, exact_line_of_sight(&g, a, b, threshold));
        }
    }

    /// In the open, the any-angle path is the straight segment, √(dx² + dy²) cells long, where
    /// the grid path is dx − dy + √2·dy.
    #[test]
    fn in_the_open_the_path_is_straight() {
        let grid = Grid {
            nx: 30,
            ny: 20,
            x_min: 0.0,
            y_min: 0.0,
            resolution_m: 1.0,
        };
        let values = vec![1.0; grid.cells()];
        let occupied = vec![false; grid.cells()];
        let g = CellGraph {
            grid: &grid,
            values: &values,
            occupied: &occupied,
        };
        let (s, t) = (grid.index(2, 3), grid.index(27, 14));
        let path = g.any_angle_path(s, t, 0.0).unwrap();
        assert_eq!(path.vertices, vec![s, t]);
        assert!((path.distance_m - 25f64.hypot(11.0)).abs() < 1e-12);
        let grid_path = g.shortest_path(s, t, 0.0).unwrap();
        assert!((grid_path.distance_m - (14.0 + 11.0 * std::f64::consts::SQRT_2)).abs() < 1e-9);
    }
}
