//! Jump point search on the feasible map's bits: the shortest-path search of path and sweep
//! queries on an indexed map (docs/model.md §6). It returns a path of the same length as
//! [`CellGraph::shortest_path`]'s A* (the same counts of orthogonal and diagonal steps, so the
//! same `distance_m` to the bit), though not always the same cells: among the many shortest
//! 8-connected paths it finds one that takes its diagonal steps first.
//!
//! Why: on an open floor the shortest 8-connected paths between two cells are legion, and A*
//! expands every cell of the parallelogram they fill. Jump point search (Harabor & Grastien,
//! AAAI 2011) expands only the cells where a shortest path may have to turn, and runs straight
//! over the rest; here it runs over 64 cells at a time, as bits (Harabor & Grastien, ICAPS 2014).
//!
//! The graph's own rules make it differ from the textbook's in one way: a diagonal step may cut
//! the corner of a cell that is free but below the threshold, not of an occupied one. A cell is
//! therefore one of three kinds (feasible, free but infeasible, occupied), and the rules below
//! that decide where a path may turn were derived for three kinds from their definition (a
//! neighbour `y` of `x` reached from `p` is kept unless a path from `p` to `y` that avoids `x`
//! is shorter, or as short when `p → x` is orthogonal); the tests check them against A* on
//! random maps of all three kinds.
//!
//! Moving orthogonally from `p` into `x` (call the move east), with N above `x`, NW above `p`
//! and NE above the next cell E (and the same below):
//! - N is kept when it is feasible and NW is occupied (the diagonal `p → N` is barred);
//! - NE is kept when it is feasible, E is not occupied and `p → N → NE` is barred: N is free
//!   but infeasible, or N is kept as above.
//!
//! Moving diagonally from `p` into `x` (call it north-east), with W and S behind `x`: NW is
//! kept when it is feasible, N is not occupied and W is free but infeasible (the way
//! `p → W → NW` is barred while `x → NW` may cut W's corner); SE likewise.
//!
//! The feasible bits of a query are worked out a 64 × 64 block at a time, when the search
//! first looks there: a word whose cells' values all lie above or all below the threshold (the
//! index keeps each word's bounds) costs one comparison, and a block's columns are its rows
//! transposed as a bit matrix.

use super::graph::{CellGraph, Infeasible, NEIGHBOURS, Path};
use rustc_hash::FxHashMap;
use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::sync::OnceLock;

/// Cells to a word of bits, and to a block's side.
const WORD: usize = 64;

/// A map's occupancy as bits along rows and along columns, and each row word's value bounds:
/// what a [`JumpIndex::shortest_path`] needs beyond the map, kept per map and unit. Its 64 × 64
/// blocks are worked out from the map when a search first looks at them, once, by whichever
/// search gets there first: a one-off query near its ends (a step across a 1001² map) costs
/// microseconds, not the 3.4 ms of the whole map. 2 KB a block, 0.5 MB on a 1001² map.
#[derive(Debug, Clone)]
pub struct JumpIndex {
    nx: usize,
    ny: usize,
    /// Words per row (bits along j): ⌈ny / 64⌉; block (bi, bj) is `blocks[bi · row_words + bj]`.
    row_words: usize,
    /// Words per column (bits along i): ⌈nx / 64⌉.
    column_words: usize,
    blocks: Vec<OnceLock<Box<Block>>>,
}

/// One 64 × 64 block of the index: rows 64·bi.. and columns 64·bj.. of the map.
#[derive(Debug, Clone)]
struct Block {
    /// Occupied cells, the block's row r as word r (bit c: column 64·bj + c); bits past the
    /// grid's end are set (off the grid reads as occupied).
    occupied_rows: [u64; WORD],
    /// The same by columns: column c as word c (bit r: row 64·bi + r).
    occupied_columns: [u64; WORD],
    /// Per row word: the least value of its free cells (NaN if one is NaN, so that no
    /// threshold finds them all feasible; +∞ when none is free) and the greatest (NaN ignored;
    /// −∞ when none).
    bounds: [[f64; 2]; WORD],
}

impl Block {
    fn new(graph: &CellGraph, bi: usize, bj: usize) -> Block {
        let (nx, ny) = (graph.grid.nx, graph.grid.ny);
        let mut block = Block {
            occupied_rows: [!0; WORD],
            occupied_columns: [!0; WORD],
            bounds: [[f64::INFINITY, f64::NEG_INFINITY]; WORD],
        };
        for r in 0..WORD.min(nx - bi * WORD) {
            let first = (bi * WORD + r) * ny + bj * WORD;
            let cells = first..first + WORD.min(ny - bj * WORD);
            let [low, high] = &mut block.bounds[r];
            for (c, (&occupied, &v)) in graph.occupied[cells.clone()]
                .iter()
                .zip(&graph.values[cells])
                .enumerate()
            {
                if occupied {
                    continue;
                }
                block.occupied_rows[r] &= !(1 << c);
                block.occupied_columns[c] &= !(1 << r);
                if v.is_nan() {
                    *low = f64::NAN;
                } else {
                    *high = high.max(v);
                    if !low.is_nan() {
                        *low = low.min(v);
                    }
                }
            }
        }
        block
    }
}

impl JumpIndex {
    /// The index of `graph`'s occupancy and values, its blocks still to be worked out.
    pub fn new(graph: &CellGraph) -> JumpIndex {
        let (nx, ny) = (graph.grid.nx, graph.grid.ny);
        let (row_words, column_words) = (ny.div_ceil(WORD), nx.div_ceil(WORD));
        JumpIndex {
            nx,
            ny,
            row_words,
            column_words,
            blocks: (0..row_words * column_words)
                .map(|_| OnceLock::new())
                .collect(),
        }
    }

    /// Block (bi, bj), worked out from `graph` (the index's) on first use.
    #[inline(always)]
    fn block(&self, graph: &CellGraph, bi: usize, bj: usize) -> &Block {
        self.blocks[bi * self.row_words + bj].get_or_init(|| Box::new(Block::new(graph, bi, bj)))
    }

    /// Every block worked out now (the service does it when it builds a map's index, off the
    /// path of the first queries).
    pub fn fill(&self, graph: &CellGraph) {
        for bi in 0..self.column_words {
            for bj in 0..self.row_words {
                self.block(graph, bi, bj);
            }
        }
    }

    /// Heap bytes the index holds once every block is worked out, for a cache's weigher.
    pub fn bytes(&self) -> usize {
        self.blocks.len()
            * (std::mem::size_of::<OnceLock<Box<Block>>>() + std::mem::size_of::<Block>())
    }

    /// The shortest feasible path from `start` to `goal` at `threshold` on `graph`, or why
    /// there is none: the length of [`CellGraph::a_star_path`]'s. `graph` must be the one the
    /// index was built from: the blocks it works out are kept, and a graph of the same size
    /// with other values or obstacles would be searched with them.
    pub fn shortest_path(
        &self,
        graph: &CellGraph,
        start: usize,
        goal: usize,
        threshold: f64,
    ) -> Result<Path, Infeasible> {
        assert_eq!(
            (graph.grid.nx, graph.grid.ny),
            (self.nx, self.ny),
            "a jump index searched on another map"
        );
        graph.check_ends(start, goal, threshold)?;
        if start == goal {
            return Ok(Path {
                cells: vec![start],
                distance_m: 0.0,
            });
        }
        super::graph::with_scratch(|scratch| {
            let mut search = Search::new(self, graph, threshold, &mut scratch.jump);
            let (cells, (orthogonal, diagonal)) =
                search.run(start, goal).ok_or(Infeasible::Disconnected)?;
            Ok(Path {
                cells,
                distance_m: super::graph::length_in_cells(orthogonal, diagonal)
                    * graph.grid.resolution_m,
            })
        })
    }
}

/// A search's working memory, kept between queries in the planner's scratch.
#[derive(Debug, Default)]
pub(super) struct JumpScratch {
    /// Feasible cells along rows and along columns, and occupied ones (copied from the index
    /// with the block), each block's 64 row words, or column words, in a run ([`slot`]).
    feasible_rows: Vec<u64>,
    feasible_columns: Vec<u64>,
    occupied_rows: Vec<u64>,
    occupied_columns: Vec<u64>,
    /// Per 64 × 64 block (block row bi, block column bj at `bi · row_words + bj`): the query
    /// whose feasible row words, and column words, it holds.
    rows_stamp: Vec<u32>,
    columns_stamp: Vec<u32>,
    query: u32,
    /// The jump points reached.
    nodes: FxHashMap<u32, JumpNode>,
    /// (f, h, cell) as f64 bits (non-negative, so ordered as integers), least f first and,
    /// among equal f, the nearer to the goal.
    open: BinaryHeap<Reverse<(u64, u64, u32)>>,
}

/// A jump point: its shortest way found (counts of orthogonal and diagonal steps, the jump
/// point it came from) and the directions it was entered by along ways of that length, and of
/// those the ones already expanded.
#[derive(Debug, Clone, Copy)]
struct JumpNode {
    orthogonal: u32,
    diagonal: u32,
    parent: u32,
    entered: u8,
    expanded: u8,
}

/// The 8 directions (di, dj), in the graph's order (orthogonal ones first): a direction's
/// index is its bit in a [`JumpNode`]'s masks.
const DIRECTIONS: [(isize, isize); 8] = {
    let mut out = [(0, 0); 8];
    let mut d = 0;
    while d < 8 {
        out[d] = (NEIGHBOURS[d].0, NEIGHBOURS[d].1);
        d += 1;
    }
    out
};

fn direction_of(di: isize, dj: isize) -> usize {
    DIRECTIONS
        .iter()
        .position(|&d| d == (di, dj))
        .expect("a unit step")
}

/// Along which of the two bit layouts a straight scan runs.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Axis {
    /// Along j, in row i's words.
    Row,
    /// Along i, in column j's words.
    Column,
}

struct Search<'a> {
    index: &'a JumpIndex,
    graph: &'a CellGraph<'a>,
    threshold: f64,
    s: &'a mut JumpScratch,
    goal: (usize, usize),
    /// The goal's length found so far (cells), +∞ before: no jump goes further.
    bound: f64,
}

/// Where a block's word r lies in the scratch's arrays: each block's 64 words in a run.
#[inline(always)]
fn slot(block: usize, r: usize) -> usize {
    block * WORD + r
}

impl<'a> Search<'a> {
    fn new(
        index: &'a JumpIndex,
        graph: &'a CellGraph<'a>,
        threshold: f64,
        s: &'a mut JumpScratch,
    ) -> Search<'a> {
        let blocks = index.blocks.len();
        if s.rows_stamp.len() != blocks {
            s.feasible_rows = vec![0; blocks * WORD];
            s.feasible_columns = vec![0; blocks * WORD];
            s.occupied_rows = vec![0; blocks * WORD];
            s.occupied_columns = vec![0; blocks * WORD];
            s.rows_stamp = vec![0; blocks];
            s.columns_stamp = vec![0; blocks];
            s.query = 0;
        }
        s.query = match s.query.checked_add(1) {
            Some(q) => q,
            None => {
                s.rows_stamp.iter_mut().for_each(|t| *t = 0);
                s.columns_stamp.iter_mut().for_each(|t| *t = 0);
                1
            }
        };
        s.nodes.clear();
        s.open.clear();
        Search {
            index,
            graph,
            threshold,
            s,
            goal: (usize::MAX, usize::MAX),
            bound: f64::INFINITY,
        }
    }

    /// Fills the row words of block (bi, bj) for this query, once.
    #[inline(always)]
    fn fill_rows(&mut self, bi: usize, bj: usize) {
        let block = bi * self.index.row_words + bj;
        if self.s.rows_stamp[block] != self.s.query {
            self.s.rows_stamp[block] = self.s.query;
            self.compute_rows(bi, bj);
        }
    }

    #[cold]
    #[inline(never)]
    fn compute_rows(&mut self, bi: usize, bj: usize) {
        let (ix, t) = (self.index, self.threshold);
        let index_block = ix.block(self.graph, bi, bj);
        let block = bi * ix.row_words + bj;
        for r in 0..WORD.min(ix.nx - bi * WORD) {
            let [low, high] = index_block.bounds[r];
            let occupied = index_block.occupied_rows[r];
            self.s.occupied_rows[slot(block, r)] = occupied;
            self.s.feasible_rows[slot(block, r)] = if high < t {
                0
            } else if low >= t {
                !occupied
            } else {
                let first = (bi * WORD + r) * ix.ny + bj * WORD;
                let cells = &self.graph.values[first..first + (ix.ny - bj * WORD).min(WORD)];
                at_least(cells, t) & !occupied
            };
        }
    }

    /// Fills the column words of block (bi, bj), once: its feasible row words, transposed.
    #[inline(always)]
    fn fill_columns(&mut self, bi: usize, bj: usize) {
        let block = bi * self.index.row_words + bj;
        if self.s.columns_stamp[block] != self.s.query {
            self.s.columns_stamp[block] = self.s.query;
            self.compute_columns(bi, bj);
        }
    }

    #[cold]
    #[inline(never)]
    fn compute_columns(&mut self, bi: usize, bj: usize) {
        self.fill_rows(bi, bj);
        let ix = self.index;
        let block = bi * ix.row_words + bj;
        let rows = WORD.min(ix.nx - bi * WORD);
        let mut m = [0u64; WORD];
        m[..rows].copy_from_slice(&self.s.feasible_rows[slot(block, 0)..slot(block, rows)]);
        transpose(&mut m);
        let columns = WORD.min(ix.ny - bj * WORD);
        self.s.feasible_columns[slot(block, 0)..slot(block, columns)]
            .copy_from_slice(&m[..columns]);
        let occupied = &ix.block(self.graph, bi, bj).occupied_columns;
        self.s.occupied_columns[slot(block, 0)..slot(block, WORD)].copy_from_slice(occupied);
    }

    /// Feasible and occupied words of `line` (a row or a column; off the grid: nothing
    /// feasible, all occupied) at word `w` (which may be one past either end).
    #[inline(always)]
    fn words(&mut self, axis: Axis, line: isize, w: isize) -> (u64, u64) {
        let ix = self.index;
        let (lines, per_line) = match axis {
            Axis::Row => (ix.nx, ix.row_words),
            Axis::Column => (ix.ny, ix.column_words),
        };
        if line < 0 || line as usize >= lines || w < 0 || w as usize >= per_line {
            return (0, !0);
        }
        let (line, w) = (line as usize, w as usize);
        match axis {
            Axis::Row => {
                self.fill_rows(line / WORD, w);
                let k = slot((line / WORD) * ix.row_words + w, line % WORD);
                (self.s.feasible_rows[k], self.s.occupied_rows[k])
            }
            Axis::Column => {
                self.fill_columns(w, line / WORD);
                let k = slot(w * ix.row_words + line / WORD, line % WORD);
                (self.s.feasible_columns[k], self.s.occupied_columns[k])
            }
        }
    }

    #[inline(always)]
    fn cell(&mut self, i: isize, j: isize) -> (bool, bool) {
        let (f, o) = self.words(Axis::Row, i, j.div_euclid(WORD as isize));
        let bit = j.rem_euclid(WORD as isize);
        (f >> bit & 1 == 1, o >> bit & 1 == 1)
    }

    #[inline]
    fn feasible(&mut self, i: isize, j: isize) -> bool {
        self.cell(i, j).0
    }

    #[inline]
    fn occupied(&mut self, i: isize, j: isize) -> bool {
        self.cell(i, j).1
    }

    /// Free but below the threshold: a diagonal step may cut its corner.
    #[inline]
    fn infeasible_free(&mut self, i: isize, j: isize) -> bool {
        self.cell(i, j) == (false, false)
    }

    /// The first cell after `from` on `line`, going `forward` (up the line's positions) or
    /// back, where a straight jump stops at a jump point: the goal, or a cell with a neighbour
    /// a shortest path may have to turn to. `None` when an infeasible cell comes first.
    /// Nothing beyond `reach` steps from `from` is looked at (a way that long could not beat the
    /// goal's length found so far).
    fn scan(
        &mut self,
        axis: Axis,
        line: isize,
        from: isize,
        forward: bool,
        reach: isize,
    ) -> Option<isize> {
        let goal_at = match axis {
            Axis::Row if self.goal.0 as isize == line => Some(self.goal.1 as isize),
            Axis::Column if self.goal.1 as isize == line => Some(self.goal.0 as isize),
            _ => None,
        };
        let word = WORD as isize;
        let step = if forward { 1 } else { -1 };
        let mut w = from.div_euclid(word);
        // Positions at or behind `from` are masked out of the first word.
        let bit = from.rem_euclid(word) as u32;
        let mut ahead = if forward {
            (!0u64).checked_shl(bit + 1).unwrap_or(0)
        } else {
            (1u64 << bit) - 1
        };
        // The (feasible, occupied) words of the line and its two sides (the line first) at
        // w − 1, w and w + 1, slid one word along per step.
        let lines = [line, line - 1, line + 1];
        let mut window = [[(0, 0); 3]; 3];
        for (l, words) in lines.iter().zip(&mut window) {
            *words = [
                self.words(axis, *l, w - 1),
                self.words(axis, *l, w),
                self.words(axis, *l, w + 1),
            ];
        }
        // Each bit k of these is the cell at position k + 1 (`up`) or k − 1 (`down`).
        let up = |x: u64, next: u64| x >> 1 | next << 63;
        let down = |x: u64, prev: u64| x << 1 | prev >> 63;
        loop {
            let [[_, (f, o), _], ..] = window;
            let [(_, o_prev), _, (_, o_next)] = window[0];
            let o_ahead = if forward {
                up(o, o_next)
            } else {
                down(o, o_prev)
            };
            let mut stop = !f;
            for &[(sf_prev, so_prev), (sf, so), (sf_next, so_next)] in &window[1..] {
                let (side_f_ahead, side_o_behind) = if forward {
                    (up(sf, sf_next), down(so, so_prev))
                } else {
                    (down(sf, sf_prev), up(so, so_next))
                };
                let side_free_infeasible = !sf & !so;
                let beside = sf & side_o_behind;
                let diagonal = side_f_ahead & !o_ahead & (side_free_infeasible | beside);
                stop |= beside | diagonal;
            }
            if let Some(g) = goal_at
                && g.div_euclid(word) == w
            {
                stop |= 1 << g.rem_euclid(word);
            }
            let hits = stop & ahead;
            if hits != 0 {
                let b = if forward {
                    hits.trailing_zeros()
                } else {
                    63 - hits.leading_zeros()
                };
                let at = w * word + b as isize;
                return (f >> b & 1 == 1 && at.abs_diff(from) <= reach as usize).then_some(at);
            }
            w += step;
            let nearest = if forward {
                w * word
            } else {
                w * word + word - 1
            };
            if nearest.abs_diff(from) > reach as usize {
                return None;
            }
            ahead = !0;
            for (l, words) in lines.iter().zip(&mut window) {
                *words = if forward {
                    [words[1], words[2], self.words(axis, *l, w + 1)]
                } else {
                    [self.words(axis, *l, w - 1), words[0], words[1]]
                };
            }
        }
    }

    /// The most steps of length `step` (cells) that keep a way of length `g` at or below the
    /// goal's length found so far (any number before the goal is reached).
    fn reach(&self, g: f64, step: f64) -> isize {
        if self.bound.is_finite() {
            ((self.bound - g) / step + 1e-9).floor().max(0.0) as isize
        } else {
            isize::MAX
        }
    }

    /// From (i, j), reached by a way of length `g` (cells), the first jump point in direction
    /// d and the steps to it.
    fn jump(
        &mut self,
        (i, j): (isize, isize),
        (di, dj): (isize, isize),
        g: f64,
    ) -> Option<(isize, isize, u32)> {
        if di == 0 {
            let k = self.scan(Axis::Row, i, j, dj > 0, self.reach(g, 1.0))?;
            return Some((i, k, k.abs_diff(j) as u32));
        }
        if dj == 0 {
            let k = self.scan(Axis::Column, j, i, di > 0, self.reach(g, 1.0))?;
            return Some((k, j, k.abs_diff(i) as u32));
        }
        let (mut a, mut b) = (i, j);
        let mut steps = 0u32;
        let most = self.reach(g, std::f64::consts::SQRT_2);
        loop {
            if steps as isize >= most {
                return None;
            }
            let (na, nb) = (a + di, b + dj);
            if !self.feasible(na, nb) || self.occupied(na, b) || self.occupied(a, nb) {
                return None;
            }
            (a, b) = (na, nb);
            steps += 1;
            let straight = self.reach(g + steps as f64 * std::f64::consts::SQRT_2, 1.0);
            if (a as usize, b as usize) == self.goal
                || self.diagonal_forced(a, b, di, dj) != 0
                || self.scan(Axis::Column, b, a, di > 0, straight).is_some()
                || self.scan(Axis::Row, a, b, dj > 0, straight).is_some()
            {
                return Some((a, b, steps));
            }
        }
    }

    /// The directions a shortest path entering (a, b) diagonally by (di, dj) may have to turn
    /// to beyond the natural three (the module's rule), as a mask of [`DIRECTIONS`].
    fn diagonal_forced(&mut self, a: isize, b: isize, di: isize, dj: isize) -> u8 {
        let mut mask = 0;
        if self.feasible(a - di, b + dj)
            && !self.occupied(a, b + dj)
            && self.infeasible_free(a - di, b)
        {
            mask |= 1 << direction_of(-di, dj);
        }
        if self.feasible(a + di, b - dj)
            && !self.occupied(a + di, b)
            && self.infeasible_free(a, b - dj)
        {
            mask |= 1 << direction_of(di, -dj);
        }
        mask
    }

    /// The same for (a, b) entered orthogonally by (di, dj).
    fn straight_forced(&mut self, a: isize, b: isize, di: isize, dj: isize) -> u8 {
        let mut mask = 0;
        // The two sides: (pi, pj) perpendicular to the move.
        for (pi, pj) in [(dj, di), (-dj, -di)] {
            let beside = self.feasible(a + pi, b + pj) && self.occupied(a + pi - di, b + pj - dj);
            if beside {
                mask |= 1 << direction_of(pi, pj);
            }
            if self.feasible(a + di + pi, b + dj + pj)
                && !self.occupied(a + di, b + dj)
                && (beside || self.infeasible_free(a + pi, b + pj))
            {
                mask |= 1 << direction_of(di + pi, dj + pj);
            }
        }
        mask
    }

    /// The directions to search from a cell entered by direction `d`: the natural ones and
    /// those the cell's neighbourhood forces.
    fn successors(&mut self, (a, b): (isize, isize), d: usize) -> u8 {
        let (di, dj) = DIRECTIONS[d];
        if di != 0 && dj != 0 {
            1 << d
                | 1 << direction_of(di, 0)
                | 1 << direction_of(0, dj)
                | self.diagonal_forced(a, b, di, dj)
        } else {
            1 << d | self.straight_forced(a, b, di, dj)
        }
    }

    /// A* over jump points from `start` to `goal` (both feasible): the path's cells, start
    /// first, and its counts of orthogonal and diagonal steps.
    fn run(&mut self, start: usize, goal: usize) -> Option<(Vec<usize>, (u64, u64))> {
        let ny = self.index.ny;
        let at = |c: usize| ((c / ny) as isize, (c % ny) as isize);
        self.goal = (goal / ny, goal % ny);
        let (gi, gj) = at(goal);
        let h = |(i, j): (isize, isize)| {
            let (dx, dy) = (i.abs_diff(gi) as f64, j.abs_diff(gj) as f64);
            dx.max(dy) + (std::f64::consts::SQRT_2 - 1.0) * dx.min(dy)
        };
        let start_node = JumpNode {
            orthogonal: 0,
            diagonal: 0,
            parent: start as u32,
            entered: 0,
            expanded: 0,
        };
        self.s.nodes.insert(start as u32, start_node);
        let h0 = h(at(start));
        self.s
            .open
            .push(Reverse((h0.to_bits(), h0.to_bits(), start as u32)));
        while let Some(Reverse((f_bits, _, cell))) = self.s.open.pop() {
            let node = self.s.nodes[&cell];
            let here = at(cell as usize);
            let g = super::graph::length_in_cells(node.orthogonal.into(), node.diagonal.into());
            if (g + h(here)).to_bits() != f_bits {
                continue; // reached again by a shorter way since
            }
            if cell as usize == goal {
                return Some((
                    self.unwind(cell),
                    (node.orthogonal.into(), node.diagonal.into()),
                ));
            }
            let directions = if cell as usize == start && node.expanded == 0 {
                0xFF
            } else {
                let pending = node.entered & !node.expanded;
                let mut out = 0;
                for d in 0..8 {
                    if pending >> d & 1 == 1 {
                        out |= self.successors(here, d);
                    }
                }
                out
            };
            if let Some(n) = self.s.nodes.get_mut(&cell) {
                n.expanded |= node.entered | u8::from(cell as usize == start);
            }
            if directions == 0 {
                continue;
            }
            // Towards the goal first: once it is reached, its length bounds every later jump.
            let toward = |&d: &usize| {
                let (di, dj) = DIRECTIONS[d];
                -(di * (gi - here.0).signum() + dj * (gj - here.1).signum())
            };
            let mut order: [usize; 8] = std::array::from_fn(|d| d);
            order.sort_by_key(toward);
            for d in order {
                let (di, dj) = DIRECTIONS[d];
                if directions >> d & 1 == 0 {
                    continue;
                }
                let Some((a, b, steps)) = self.jump(here, (di, dj), g) else {
                    continue;
                };
                let (orthogonal, diagonal) = if di != 0 && dj != 0 {
                    (node.orthogonal, node.diagonal + steps)
                } else {
                    (node.orthogonal + steps, node.diagonal)
                };
                let to = (a as usize * ny + b as usize) as u32;
                let length = super::graph::length_in_cells(orthogonal.into(), diagonal.into());
                if to as usize == goal {
                    self.bound = self.bound.min(length);
                }
                let push = match self.s.nodes.get_mut(&to) {
                    Some(n) if (n.orthogonal, n.diagonal) == (orthogonal, diagonal) => {
                        let new = n.entered & 1 << d == 0;
                        n.entered |= 1 << d;
                        new
                    }
                    Some(n)
                        if length
                            >= super::graph::length_in_cells(
                                n.orthogonal.into(),
                                n.diagonal.into(),
                            ) =>
                    {
                        false
                    }
                    _ => {
                        self.s.nodes.insert(
                            to,
                            JumpNode {
                                orthogonal,
                                diagonal,
                                parent: cell,
                                entered: 1 << d,
                                expanded: 0,
                            },
                        );
                        true
                    }
                };
                if push {
                    let hb = h((a, b));
                    self.s
                        .open
                        .push(Reverse(((length + hb).to_bits(), hb.to_bits(), to)));
                }
            }
        }
        None
    }

    /// The cells from the start to `cell`, each jump filled in step by step.
    fn unwind(&self, mut cell: u32) -> Vec<usize> {
        let ny = self.index.ny as isize;
        let mut cells = vec![cell as usize];
        loop {
            let parent = self.s.nodes[&cell].parent;
            if parent == cell {
                break;
            }
            let (ci, cj) = (cell as isize / ny, cell as isize % ny);
            let (pi, pj) = (parent as isize / ny, parent as isize % ny);
            let (di, dj) = ((pi - ci).signum(), (pj - cj).signum());
            let (mut i, mut j) = (ci, cj);
            while (i, j) != (pi, pj) {
                (i, j) = (i + di, j + dj);
                cells.push((i * ny + j) as usize);
            }
            cell = parent;
        }
        cells.reverse();
        cells
    }
}

/// Bit k set where `cells[k] >= t` (at most 64 cells). Eight at a time into a byte, a shape
/// the compiler turns into vector compares and a mask move; a bit at a time was a third of
/// the search's time, on the words that straddle the threshold.
#[inline]
fn at_least(cells: &[f64], t: f64) -> u64 {
    let mut bits = 0u64;
    let mut chunks = cells.chunks_exact(8);
    for (c, chunk) in (&mut chunks).enumerate() {
        let chunk: &[f64; 8] = chunk.try_into().expect("eight");
        let mut byte = 0u8;
        for (k, &v) in chunk.iter().enumerate() {
            byte |= u8::from(v >= t) << k;
        }
        bits |= u64::from(byte) << (8 * c);
    }
    let done = cells.len() - chunks.remainder().len();
    for (k, &v) in chunks.remainder().iter().enumerate() {
        bits |= u64::from(v >= t) << (done + k);
    }
    bits
}

/// Transposes a 64 × 64 bit matrix in place: bit c of word r goes to bit r of word c (the
/// recursive block swap of Hacker's Delight §7-3, least significant bit first).
fn transpose(m: &mut [u64; WORD]) {
    let mut width = 32;
    let mut mask: u64 = 0x0000_0000_FFFF_FFFF;
    while width != 0 {
        let mut k = 0;
        while k < WORD {
            let t = (m[k] >> width ^ m[k + width]) & mask;
            m[k] ^= t << width;
            m[k + width] ^= t;
            k = (k + width + 1) & !width;
        }
        width >>= 1;
        mask ^= mask << width;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Grid;
    use proptest::prelude::*;

    #[test]
    fn transpose_moves_every_bit_across_the_diagonal() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(0x9E37_79B9_7F4A_7C15);
        let mut m: [u64; WORD] = std::array::from_fn(|_| rng.random());
        let original = m;
        transpose(&mut m);
        for (r, row) in original.iter().enumerate() {
            for (c, column) in m.iter().enumerate() {
                assert_eq!(column >> r & 1, row >> c & 1, "({r}, {c})");
            }
        }
    }

    /// Maps of the three kinds of cell on grids up to 70 cells a side (words and blocks end
    /// inside them): values in 0..4, NaN here and there, occupied cells.
    fn arb_map() -> impl Strategy<Value = (usize, usize, Vec<f64>, Vec<bool>)> {
        (1usize..70, 1usize..70, 0u8..3).prop_flat_map(|(nx, ny, density)| {
            let n = nx * ny;
            let occupied_share = [0.0, 0.1, 0.3][density as usize];
            (
                Just(nx),
                Just(ny),
                prop::collection::vec(
                    prop_oneof![9 => (0u8..4).prop_map(f64::from), 1 => Just(f64::NAN)],
                    n,
                ),
                prop::collection::vec(prop::bool::weighted(occupied_share), n),
            )
        })
    }

    fn check(
        nx: usize,
        ny: usize,
        values: &[f64],
        occupied: &[bool],
        queries: &[(usize, usize, f64)],
    ) {
        let grid = Grid {
            nx,
            ny,
            x_min: 0.0,
            y_min: 0.0,
            resolution_m: 0.5,
        };
        let graph = CellGraph {
            grid: &grid,
            values,
            occupied,
        };
        let index = JumpIndex::new(&graph);
        for &(s, g, t) in queries {
            let expected = graph.a_star_path(s, g, t);
            let found = index.shortest_path(&graph, s, g, t);
            match (&expected, &found) {
                (Ok(a), Ok(b)) => {
                    assert_eq!(a.distance_m, b.distance_m, "{s} → {g} at {t}");
                    assert_eq!(b.cells.first(), Some(&s));
                    assert_eq!(b.cells.last(), Some(&g));
                    // Every step is a move of the graph.
                    for pair in b.cells.windows(2) {
                        let mut ok = false;
                        graph.for_each_neighbour(pair[0], |n, _, _| ok |= n == pair[1]);
                        assert!(ok && graph.is_feasible(pair[1], t), "{pair:?}");
                    }
                }
                (a, b) => assert_eq!(a.as_ref().err(), b.as_ref().err(), "{s} → {g} at {t}"),
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(400))]
        #[test]
        fn lengths_equal_a_stars(
            (nx, ny, values, occupied) in arb_map(),
            ends in prop::collection::vec((any::<prop::sample::Index>(), any::<prop::sample::Index>(), 0u8..4), 12),
        ) {
            let n = nx * ny;
            let queries: Vec<_> = ends
                .iter()
                .map(|(s, g, t)| (s.index(n), g.index(n), f64::from(*t)))
                .collect();
            check(nx, ny, &values, &occupied, &queries);
        }
    }

    /// A long exhaustive sweep over small maps of the three kinds: every pair of cells.
    #[test]
    fn every_pair_on_small_maps() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(0x2545_F491_4F6C_DD1D);
        let mut next = || rng.random::<u64>();
        for _ in 0..100 {
            let (nx, ny) = (2 + next() as usize % 7, 2 + next() as usize % 7);
            let n = nx * ny;
            let occupied: Vec<bool> = (0..n).map(|_| next() % 5 == 0).collect();
            let values: Vec<f64> = (0..n).map(|_| (next() % 3) as f64).collect();
            let queries: Vec<_> = (0..n)
                .flat_map(|s| (0..n).map(move |g| (s, g, 1.0)))
                .collect();
            check(nx, ny, &values, &occupied, &queries);
        }
    }
}
