//! Outlines of a set of grid cells as simple polygons, for zones a fleet manager loads (VDA 5050
//! zone sets): each cell is its square, and the set is covered — never shrunk — by polygons that
//! are simple (no self-touching), hole-free, disjoint and counterclockwise.
//!
//! Two steps make the outline of any set such polygons, both only ever adding cells:
//! * **holes are filled**: a cell outside the set that cannot reach the grid's edge through
//!   other such cells (4-connected) joins it. For a BLOCKED zone this blocks nothing a robot
//!   could reach without crossing the zone;
//! * **pinches are filled**: where two cells of the set touch only at a corner (a 2 × 2 window
//!   set on one diagonal only), the outline would pass that corner twice and not be simple, so
//!   the window's other two cells join the set; filling can close new holes, so both steps
//!   repeat until nothing changes.
//!
//! The outline of the result is then one simple closed curve per 4-connected component: its
//! boundary edges, each cell side between the set and the rest, oriented with the set on the
//! left, leave every lattice corner at most once, so following them traces each curve; runs of
//! collinear edges become one edge.

use crate::scenario::Grid;

/// A polygon's vertices (x, y) (m), counterclockwise, without repeating the first.
pub type Polygon = Vec<[f64; 2]>;

/// The cell set `cells` (flat index `i·ny + j`, as [`Grid::index`]) after holes and pinches are
/// filled (see the module's notes): a superset whose outline is simple.
pub fn filled(grid: &Grid, cells: &[bool]) -> Vec<bool> {
    let (nx, ny) = (grid.nx, grid.ny);
    let mut set = cells.to_vec();
    loop {
        fill_holes(nx, ny, &mut set);
        if !fill_pinches(nx, ny, &mut set) {
            return set;
        }
    }
}

/// Cells outside the set that no path of such cells joins to the grid's edge join the set.
fn fill_holes(nx: usize, ny: usize, set: &mut [bool]) {
    let mut outside = vec![false; set.len()];
    let mut stack: Vec<usize> = Vec::new();
    let seed = |k: usize, outside: &mut [bool], stack: &mut Vec<usize>| {
        if !set[k] && !outside[k] {
            outside[k] = true;
            stack.push(k);
        }
    };
    for i in 0..nx {
        seed(i * ny, &mut outside, &mut stack);
        seed(i * ny + ny - 1, &mut outside, &mut stack);
    }
    for j in 0..ny {
        seed(j, &mut outside, &mut stack);
        seed((nx - 1) * ny + j, &mut outside, &mut stack);
    }
    while let Some(k) = stack.pop() {
        let (i, j) = (k / ny, k % ny);
        let neighbours = [
            (i > 0).then(|| k - ny),
            (i + 1 < nx).then(|| k + ny),
            (j > 0).then(|| k - 1),
            (j + 1 < ny).then(|| k + 1),
        ];
        for n in neighbours.into_iter().flatten() {
            if !set[n] && !outside[n] {
                outside[n] = true;
                stack.push(n);
            }
        }
    }
    for (cell, out) in set.iter_mut().zip(&outside) {
        *cell = !*out;
    }
}

/// Fills every 2 × 2 window set on one diagonal only; says whether any was.
fn fill_pinches(nx: usize, ny: usize, set: &mut [bool]) -> bool {
    let mut changed = false;
    for i in 0..nx.saturating_sub(1) {
        for j in 0..ny.saturating_sub(1) {
            let (a, b, c, d) = (
                i * ny + j,
                (i + 1) * ny + j,
                i * ny + j + 1,
                (i + 1) * ny + j + 1,
            );
            if set[a] == set[d] && set[b] == set[c] && set[a] != set[b] {
                for k in [a, b, c, d] {
                    set[k] = true;
                }
                changed = true;
            }
        }
    }
    changed
}

/// The outline of `cells` (which [`filled`] makes first): one counterclockwise simple polygon
/// per 4-connected component, each cell its square of side Δ around its centre, clipped to the
/// grid's extent (the room: the outer cells' centres lie on its walls). A grid has at least
/// two cells each way (a validated scenario's does), so every polygon has an area.
pub fn outline(grid: &Grid, cells: &[bool]) -> Vec<Polygon> {
    let set = filled(grid, cells);
    let (nx, ny) = (grid.nx, grid.ny);
    // Lattice corner (a, b) is the lower-left corner of cell (a, b): (nx + 1) × (ny + 1) of them.
    let corner = |a: usize, b: usize| a * (ny + 1) + b;
    let inside = |i: isize, j: isize| {
        i >= 0
            && j >= 0
            && (i as usize) < nx
            && (j as usize) < ny
            && set[i as usize * ny + j as usize]
    };
    // The one boundary edge leaving each corner (set on its left), if any.
    let mut next = vec![usize::MAX; (nx + 1) * (ny + 1)];
    for i in 0..nx {
        for j in 0..ny {
            if !set[i * ny + j] {
                continue;
            }
            let (si, sj) = (i as isize, j as isize);
            if !inside(si, sj - 1) {
                next[corner(i, j)] = corner(i + 1, j);
            }
            if !inside(si + 1, sj) {
                next[corner(i + 1, j)] = corner(i + 1, j + 1);
            }
            if !inside(si, sj + 1) {
                next[corner(i + 1, j + 1)] = corner(i, j + 1);
            }
            if !inside(si - 1, sj) {
                next[corner(i, j + 1)] = corner(i, j);
            }
        }
    }
    let (x_max, y_max) = (
        grid.x_min + (nx - 1) as f64 * grid.resolution_m,
        grid.y_min + (ny - 1) as f64 * grid.resolution_m,
    );
    let position = |c: usize| {
        let (a, b) = (c / (ny + 1), c % (ny + 1));
        [
            (grid.x_min + (a as f64 - 0.5) * grid.resolution_m).clamp(grid.x_min, x_max),
            (grid.y_min + (b as f64 - 0.5) * grid.resolution_m).clamp(grid.y_min, y_max),
        ]
    };
    let mut polygons = Vec::new();
    for start in 0..next.len() {
        if next[start] == usize::MAX {
            continue;
        }
        // Follow the curve from `start`, taking each edge once and keeping only the corners
        // where it turns.
        let mut corners = Vec::new();
        let mut at = start;
        loop {
            let to = std::mem::replace(&mut next[at], usize::MAX);
            corners.push(at);
            at = to;
            if at == start {
                break;
            }
        }
        let n = corners.len();
        let lattice = |c: usize| ((c / (ny + 1)) as isize, (c % (ny + 1)) as isize);
        let polygon: Polygon = (0..n)
            .filter(|&k| {
                let (p, q, r) = (
                    lattice(corners[(k + n - 1) % n]),
                    lattice(corners[k]),
                    lattice(corners[(k + 1) % n]),
                );
                (q.0 - p.0, q.1 - p.1) != (r.0 - q.0, r.1 - q.1)
            })
            .map(|k| position(corners[k]))
            .collect();
        polygons.push(polygon);
    }
    polygons
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
            resolution_m: 1.0,
        }
    }

    /// Twice the signed area (positive: counterclockwise).
    fn twice_area(p: &Polygon) -> f64 {
        (0..p.len())
            .map(|k| {
                let (a, b) = (p[k], p[(k + 1) % p.len()]);
                a[0] * b[1] - b[0] * a[1]
            })
            .sum()
    }

    /// Whether `q` lies strictly inside `p` (even-odd rule; `q` never on an edge here).
    fn contains(p: &Polygon, q: [f64; 2]) -> bool {
        let mut inside = false;
        for k in 0..p.len() {
            let (a, b) = (p[k], p[(k + 1) % p.len()]);
            if (a[1] > q[1]) != (b[1] > q[1])
                && q[0] < a[0] + (q[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            {
                inside = !inside;
            }
        }
        inside
    }

    /// Whether the closed segments ab and cd share a point, exactly (axis-parallel segments
    /// with coordinates on a half-integer lattice).
    fn meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
        let lo = |u: f64, v: f64| u.min(v);
        let hi = |u: f64, v: f64| u.max(v);
        lo(a[0], b[0]) <= hi(c[0], d[0])
            && lo(c[0], d[0]) <= hi(a[0], b[0])
            && lo(a[1], b[1]) <= hi(c[1], d[1])
            && lo(c[1], d[1]) <= hi(a[1], b[1])
    }

    /// A ring's outline has no hole; two cells touching at a corner become one square block.
    #[test]
    fn holes_and_pinches_are_filled() {
        let g = grid(5, 5);
        let mut ring = vec![false; 25];
        for (i, j) in [
            (1, 1),
            (2, 1),
            (3, 1),
            (1, 2),
            (3, 2),
            (1, 3),
            (2, 3),
            (3, 3),
        ] {
            ring[i * 5 + j] = true;
        }
        let polygons = outline(&g, &ring);
        assert_eq!(
            polygons,
            vec![vec![[0.5, 0.5], [3.5, 0.5], [3.5, 3.5], [0.5, 3.5]]]
        );
        let mut diagonal = vec![false; 25];
        diagonal[5 + 1] = true;
        diagonal[2 * 5 + 2] = true;
        let polygons = outline(&g, &diagonal);
        assert_eq!(
            polygons,
            vec![vec![[0.5, 0.5], [2.5, 0.5], [2.5, 2.5], [0.5, 2.5]]]
        );
    }

    /// Cells on the grid's edge are clipped to the room (their centres lie on its walls).
    #[test]
    fn outlines_stop_at_the_walls() {
        let g = grid(3, 2);
        let polygons = outline(&g, &[true; 6]);
        assert_eq!(
            polygons,
            vec![vec![[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]]]
        );
        assert!(outline(&g, &[false; 6]).is_empty());
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

        /// On random sets: every cell of the set lies in exactly one polygon, every cell the
        /// polygons cover is in the filled set (so the outline adds only holes and pinches), the
        /// polygons are counterclockwise, rectilinear and simple (no two non-adjacent edges
        /// meet), with turns at every vertex, and their areas add up to the filled set's.
        #[test]
        fn outlines_cover_exactly_the_filled_set_with_simple_polygons(
            nx in 2usize..9, ny in 2usize..9, bits in proptest::collection::vec(any::<bool>(), 64),
        ) {
            // A grid away from the origin with 1 m cells, unclipped but for the outer half cells.
            let g = Grid { nx, ny, x_min: 3.0, y_min: -2.0, resolution_m: 1.0 };
            let cells: Vec<bool> = bits[..nx * ny].to_vec();
            let set = filled(&g, &cells);
            prop_assert!(cells.iter().zip(&set).all(|(c, s)| !c || *s), "never shrunk");
            let polygons = outline(&g, &cells);
            for i in 0..nx {
                for j in 0..ny {
                    // A point of the cell's square inside the room, on no lattice line.
                    let off = |k: usize, n: usize| if k + 1 == n { -0.25 } else { 0.25 };
                    let centre = [g.x_min + i as f64 + off(i, nx), g.y_min + j as f64 + off(j, ny)];
                    let holding = polygons.iter().filter(|p| contains(p, centre)).count();
                    prop_assert_eq!(holding, usize::from(set[i * ny + j]), "cell ({}, {})", i, j);
                }
            }
            let clipped_area: f64 = (0..nx).flat_map(|i| (0..ny).map(move |j| (i, j)))
                .filter(|(i, j)| set[i * ny + j])
                .map(|(i, j)| {
                    let w = if i == 0 || i == nx - 1 { 0.5 } else { 1.0 };
                    let h = if j == 0 || j == ny - 1 { 0.5 } else { 1.0 };
                    w * h
                })
                .sum();
            let area: f64 = polygons.iter().map(|p| twice_area(p) / 2.0).sum();
            prop_assert!((area - clipped_area).abs() < 1e-9, "area {} vs {}", area, clipped_area);
            for p in &polygons {
                let n = p.len();
                prop_assert!(n >= 4 && n % 2 == 0);
                prop_assert!(twice_area(p) > 0.0, "counterclockwise");
                for k in 0..n {
                    let (a, b, c) = (p[k], p[(k + 1) % n], p[(k + 2) % n]);
                    prop_assert!(a[0] == b[0] || a[1] == b[1], "rectilinear");
                    prop_assert!((a[0] == b[0]) != (b[0] == c[0]), "a turn at every vertex");
                    for m in k + 2..n {
                        if (m + 1) % n == k {
                            continue;
                        }
                        prop_assert!(!meet(a, b, p[m], p[(m + 1) % n]), "edges {} and {} meet", k, m);
                    }
                }
            }
        }
    }
}
