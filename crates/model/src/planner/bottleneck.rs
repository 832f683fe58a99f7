//! The widest-path threshold of every pair of cells of one map, answered in O(log cells) from an
//! index built once per map (docs/model.md §6).
//!
//! A served map answers many path queries, and each one reports the largest threshold for which
//! any path joins its ends (`max_feasible_threshold`). [`CellGraph::widest_path_threshold`]
//! finds it by a search over the map, 3–4 ms on a 1001² floor, as long as the shortest path
//! itself; this index answers in well under a microsecond after a build of about as long as
//! thirty such searches.
//!
//! The feasible map Π(γ) (paper eq. 14) only grows as γ falls. Activating the free cells in
//! order of falling value and joining each to its active neighbours (a union-find, Kruskal's
//! algorithm on the cell graph) therefore replays Π(γ) for every γ at once: two cells are joined
//! by a feasible path at γ exactly when they share a component once every cell of value ≥ γ is
//! active. The union-find is linked by size and never compressed, so it keeps each link, and a
//! tree of it has depth ≤ log₂ cells; each link remembers the cell whose activation made it.
//! Two cells' components merged at the smallest value recorded on the tree path between them,
//! which is their widest-path threshold.
//!
//! The neighbours are [`CellGraph`]'s own (free cells, no cut occupied corner), so the index and
//! the search agree by construction; a property test checks that they agree on random maps.

use super::graph::CellGraph;

/// Marks a cell that is never activated: occupied, or valued NaN or −∞, so that no path through
/// it has a finite width.
const INACTIVE: u32 = u32::MAX;

/// Depth bound of a union-find tree linked by size: log₂ of the largest grid, rounded up, plus
/// one (a tree of depth d holds at least 2^d cells).
const MAX_DEPTH: usize =
    1 + (usize::BITS - crate::scenario::MAX_GRID_CELLS.leading_zeros()) as usize;

/// The union-find forest of one map's cells after every cell has been activated.
#[derive(Debug, Clone)]
pub struct Bottlenecks {
    /// Each cell's parent (itself at a root), or [`INACTIVE`].
    parent: Vec<u32>,
    /// For a linked cell, the cell whose activation linked it to its parent: the link exists
    /// for every threshold at or below that cell's value. Stored as a cell (4 bytes) rather than
    /// its value (8), which the map keeps anyway.
    linked_by: Vec<u32>,
}

impl Bottlenecks {
    /// Builds the index of a map's graph: a sort of the cells by value, then one union per
    /// pair of neighbours (O(cells · log cells)).
    pub fn new(graph: &CellGraph) -> Bottlenecks {
        let cells = graph.values.len();
        let active_value = |c: usize| {
            let v = graph.values[c];
            (!graph.occupied[c] && v > f64::NEG_INFINITY).then_some(v)
        };
        let mut order: Vec<u32> = (0..cells as u32)
            .filter(|&c| active_value(c as usize).is_some())
            .collect();
        // Falling value; among equal values by index, so that the index does not depend on the
        // sort's stability (any order of equal values gives the same thresholds).
        order.sort_unstable_by(|&a, &b| {
            graph.values[b as usize]
                .total_cmp(&graph.values[a as usize])
                .then(a.cmp(&b))
        });
        let mut parent = vec![INACTIVE; cells];
        let mut linked_by = vec![INACTIVE; cells];
        // Component sizes at the roots, for linking the smaller tree under the larger.
        let mut size = vec![1u32; cells];
        let root = |parent: &[u32], mut c: u32| {
            while parent[c as usize] != c {
                c = parent[c as usize];
            }
            c
        };
        for &cell in &order {
            parent[cell as usize] = cell;
            graph.for_each_neighbour(cell as usize, |n, _, _| {
                if parent[n] == INACTIVE {
                    return;
                }
                let (a, b) = (root(&parent, cell), root(&parent, n as u32));
                if a == b {
                    return;
                }
                let (small, large) = if size[a as usize] < size[b as usize] {
                    (a, b)
                } else {
                    (b, a)
                };
                parent[small as usize] = large;
                linked_by[small as usize] = cell;
                size[large as usize] += size[small as usize];
            });
        }
        Bottlenecks { parent, linked_by }
    }

    /// The largest threshold γ for which a feasible path joins `start` and `goal` on the map the
    /// index was built from (`values` are its values): the same answer as
    /// [`CellGraph::widest_path_threshold`].
    pub fn widest_path_threshold(&self, values: &[f64], start: usize, goal: usize) -> Option<f64> {
        if self.parent[start] == INACTIVE || self.parent[goal] == INACTIVE {
            return None;
        }
        let width = if start == goal {
            values[start]
        } else {
            // The start's ancestors, each with the narrowest link on the way up to it.
            let mut chain = [(0u32, f64::INFINITY); MAX_DEPTH];
            let (mut depth, mut c, mut narrowest) = (0, start as u32, f64::INFINITY);
            loop {
                chain[depth] = (c, narrowest);
                depth += 1;
                let up = self.parent[c as usize];
                if up == c {
                    break;
                }
                narrowest = narrowest.min(values[self.linked_by[c as usize] as usize]);
                c = up;
            }
            // Up from the goal until the first common ancestor.
            let (mut c, mut narrowest) = (goal as u32, f64::INFINITY);
            loop {
                if let Some(&(_, from_start)) = chain[..depth].iter().find(|(a, _)| *a == c) {
                    break narrowest.min(from_start);
                }
                let up = self.parent[c as usize];
                if up == c {
                    return None;
                }
                narrowest = narrowest.min(values[self.linked_by[c as usize] as usize]);
                c = up;
            }
        };
        width.is_finite().then_some(width)
    }

    /// Heap bytes held, for a cache's weigher.
    pub fn bytes(&self) -> usize {
        (self.parent.capacity() + self.linked_by.capacity()) * std::mem::size_of::<u32>()
    }
}
