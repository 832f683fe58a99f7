//! Passages the conservative occupancy closes (docs/model.md §1, Occupancy): a door or a gap
//! that a robot could drive through, but that no chain of free grid cells crosses because every
//! cell in it overlaps an obstacle. Reported with each map so that users know where to refine
//! the grid.
//!
//! A *narrowed* cell is occupied by the conservative rule while its centre (widened by the
//! robot's radius) is clear. Narrowed cells are grouped with their 8-neighbours wherever the
//! floor-level segment between the two centres crosses no obstacle, so a thin wall never joins
//! the cells on its two sides. A group whose cells touch (again by an unobstructed segment) free
//! cells of two or more components of the free space is a closed passage: with a finer grid those
//! components may join.

use crate::geometry::Nearby;
use crate::scenario::{Grid, Scenario};
use serde::Serialize;
use std::collections::VecDeque;

/// Most passages listed per map (the largest first); the count covers them all.
pub const MAX_LISTED: usize = 100;

/// One passage closed by the conservative occupancy.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ClosedPassage {
    /// x of the narrowed cell where it meets a second component (m): the door itself, where
    /// the narrowed strip along a wall runs past it.
    pub x: f64,
    /// y of that cell (m).
    pub y: f64,
    /// Narrowed cells in its group.
    pub cells: usize,
    /// How many components of the free space it would join.
    pub joins: usize,
}

/// The passages a map's occupancy closes: the largest [`MAX_LISTED`] and how many in all.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ClosedPassages {
    /// The passages, largest first.
    pub listed: Vec<ClosedPassage>,
    /// How many there are, listed or not.
    pub total: usize,
}

/// The passages the conservative occupancy `occupied` closes on `grid`.
pub fn closed_passages(scenario: &Scenario, grid: &Grid, occupied: &[bool]) -> ClosedPassages {
    // The centre's own square: 1 µm wide beyond the radius, above the 10⁻⁹ m below which
    // footprints are taken to touch rather than overlap.
    let centre_blocked = super::overlapped(scenario, grid, scenario.mru.radius_m + 1e-6);
    let narrowed: Vec<bool> = occupied
        .iter()
        .zip(&centre_blocked)
        .map(|(&square, &centre)| square && !centre)
        .collect();
    if !narrowed.iter().any(|&n| n) {
        return ClosedPassages::default();
    }
    let component = free_components(grid, occupied);
    // A step from a narrowed cell's centre to a neighbour's, shifted by ε, stays in the square
    // of half-side 1.01 Δ around the first.
    let obstructions = scenario.obstructions();
    let nearby = Nearby::new(&obstructions, grid, &narrowed, 1.01 * grid.resolution_m);
    // Low above the floor: what a robot drives through. A segment that only grazes an
    // obstacle (along a wall's end face) is not a way through, so the two segments beside it,
    // ε to either side, must be clear too.
    let z = 1e-3;
    let eps = 1e-4 * grid.resolution_m;
    let clear = |a: usize, b: usize| {
        let (p, q) = (grid.cell_of(a), grid.cell_of(b));
        let ([x0, y0], [x1, y1]) = (grid.centre(p.0, p.1), grid.centre(q.0, q.1));
        let length = (x1 - x0).hypot(y1 - y0);
        let (nx, ny) = (-(y1 - y0) / length * eps, (x1 - x0) / length * eps);
        [0.0, 1.0, -1.0].iter().all(|&k| {
            !nearby.blocks(
                a,
                [x0 + k * nx, y0 + k * ny, z],
                [x1 + k * nx, y1 + k * ny, z],
            )
        })
    };
    let mut seen = vec![false; grid.cells()];
    let mut passages = Vec::new();
    for first in 0..grid.cells() {
        if !narrowed[first] || seen[first] {
            continue;
        }
        seen[first] = true;
        let mut queue = VecDeque::from([first]);
        let mut cells = 0usize;
        let mut joins: Vec<u32> = Vec::new();
        let mut at = None;
        while let Some(c) = queue.pop_front() {
            cells += 1;
            for n in neighbours(grid, c) {
                if narrowed[n] && !seen[n] && clear(c, n) {
                    seen[n] = true;
                    queue.push_back(n);
                } else if !occupied[n] && !joins.contains(&component[n]) && clear(c, n) {
                    joins.push(component[n]);
                    if joins.len() == 2 {
                        let (i, j) = grid.cell_of(c);
                        at = Some(grid.centre(i, j));
                    }
                }
            }
        }
        if let Some([x, y]) = at {
            passages.push(ClosedPassage {
                x,
                y,
                cells,
                joins: joins.len(),
            });
        }
    }
    let total = passages.len();
    passages.sort_by(|a, b| b.cells.cmp(&a.cells).then(a.x.total_cmp(&b.x)));
    passages.truncate(MAX_LISTED);
    ClosedPassages {
        listed: passages,
        total,
    }
}

/// The 8 neighbours of a cell on the grid (any occupancy).
fn neighbours(grid: &Grid, c: usize) -> impl Iterator<Item = usize> + '_ {
    let (i, j) = grid.cell_of(c);
    (-1isize..=1)
        .flat_map(|di| (-1isize..=1).map(move |dj| (di, dj)))
        .filter(|&d| d != (0, 0))
        .filter_map(move |(di, dj)| {
            let (a, b) = (i.checked_add_signed(di)?, j.checked_add_signed(dj)?);
            (a < grid.nx && b < grid.ny).then(|| grid.index(a, b))
        })
}

/// Each free cell's component of the free space under the planner's moves (8-neighbours, a
/// diagonal only between two free orthogonal neighbours); `u32::MAX` for occupied cells.
fn free_components(grid: &Grid, occupied: &[bool]) -> Vec<u32> {
    let mut component = vec![u32::MAX; grid.cells()];
    let mut next = 0u32;
    let mut queue = VecDeque::new();
    for first in 0..grid.cells() {
        if occupied[first] || component[first] != u32::MAX {
            continue;
        }
        component[first] = next;
        queue.push_back(first);
        while let Some(c) = queue.pop_front() {
            let (i, j) = grid.cell_of(c);
            for n in neighbours(grid, c) {
                let (a, b) = grid.cell_of(n);
                let diagonal = a != i && b != j;
                if occupied[n]
                    || component[n] != u32::MAX
                    || (diagonal && (occupied[grid.index(a, j)] || occupied[grid.index(i, b)]))
                {
                    continue;
                }
                component[n] = next;
                queue.push_back(n);
            }
        }
        next += 1;
    }
    component
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The small room (6 × 4 m at 0.5 m) split by a 10 cm wall at x = 3.2 m with a door
    /// (`gap` m wide, centred at y = 1.75 m): a door narrower than a cell is closed by the
    /// conservative occupancy and reported at the door; a wide one is not; a wall without a door
    /// closes nothing (its two sides are not joined through it).
    #[test]
    fn a_door_narrower_than_a_cell_is_reported_where_it_is() {
        let with_door = |gap: Option<f64>| -> (ClosedPassages, Vec<bool>, Grid) {
            let s = Scenario::builtin_with("small-test", |value| {
            value["obstacles"] = serde_json::json!([]);
            value["walls"] = match gap {
                Some(g) => serde_json::json!([
                    {"from": [3.2, 0.0], "to": [3.2, 1.75 - g / 2.0], "thickness_m": 0.1, "height_m": 2.0},
                    {"from": [3.2, 1.75 + g / 2.0], "to": [3.2, 4.0], "thickness_m": 0.1, "height_m": 2.0},
                ]),
                None => serde_json::json!([
                    {"from": [3.2, 0.0], "to": [3.2, 4.0], "thickness_m": 0.1, "height_m": 2.0},
                ]),
            };
            })
            .unwrap()
            .unwrap();
            let grid = s.grid();
            let occupied = super::super::occupancy(&s, &grid);
            (closed_passages(&s, &grid, &occupied), occupied, grid)
        };
        let (narrow, occupied, grid) = with_door(Some(0.3));
        assert_eq!(narrow.total, 1, "{narrow:?}");
        let p = &narrow.listed[0];
        assert_eq!(p.joins, 2);
        assert!(
            (p.x - 3.0).abs() < 1e-9 && (1.5..=2.0).contains(&p.y),
            "{p:?}"
        );
        // And indeed no free cell of the right half is reachable from the left one.
        let component = free_components(&grid, &occupied);
        let (left, right) = (grid.index(0, 0), grid.index(12, 0));
        assert_ne!(component[left], component[right]);
        let (wide, _, _) = with_door(Some(1.6));
        assert_eq!(wide.total, 0, "{wide:?}");
        let (walled, _, _) = with_door(None);
        assert_eq!(walled.total, 0, "{walled:?}");
    }
}
