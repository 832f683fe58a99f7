//! What stands on the floor, as the channel model and the grid see it (docs/model.md §1): boxes,
//! walls at any angle and an occupancy raster (a ROS floor plan), with the two questions asked
//! of them: does a link's 3D segment pass through the *interior* of something (blockage), and
//! does a grid cell's centre lie *in or on* something (occupancy).
//!
//! Both rules are the same for the three kinds, so a floor drawn as boxes, as walls or as pixels
//! gives the same map:
//! * blockage needs the open interior: a segment that only grazes a face, an edge or a corner is
//!   LoS (a ray along the top of a shelf is not blocked by it);
//! * occupancy is closed: a cell centre on the boundary is occupied (the robot keeps off the
//!   edge).
//!
//! The raster is tested by walking the pixels the segment's 2D projection crosses, column by
//! column along its major axis and leaping through open floor, so a link costs at most
//! O(pixels crossed) whatever the number of walls drawn into the image.

use nalgebra::Vector3;

mod nearby;
mod raster;
mod sightlines;
pub use nearby::Nearby;
pub use raster::{Blocker, Horizon, Raster, Settled};
pub use sightlines::SightLines;

type P3 = Vector3<f64>;

/// A segment overlapping a box for less than this fraction of its length only grazes it: well
/// below any physical size (1e-12 of a 30 m link is 30 fm), above the rounding of the slab
/// arithmetic.
const GRAZE_T: f64 = 1e-12;

/// Closeness (m) below which a point counts as on a box's boundary for occupancy, so centres
/// typed to the nanometre on an edge are occupied as intended.
const ON_BOUNDARY_M: f64 = 1e-9;

/// How deep (m) a segment must reach into an obstacle's interior, on every axis, to be
/// blocked by it. A decimal coordinate is rarely a double (a cell centre at 117 · 0.05 m is
/// 5.8500000000000005), so a link typed to run along a face at 5.85 would otherwise enter the
/// box by 5·10⁻¹⁶ m and count as blocked. 10⁻⁹ m is a million times the rounding of room-sized
/// coordinates, and far below the depth by which a link between decimal points that truly
/// crosses an obstacle enters it: at least u / (2 D²) for points and faces on a lattice of step
/// u across D steps (1.6·10⁻⁷ m for 5 cm over 20 m; docs/model.md §2 "Links"), which a property
/// test checks against exact rational arithmetic.
pub const GRAZE_M: f64 = 1e-9;

/// The parameters t where the line p + t(q − p) lies inside the open slab (lo, hi) of one axis,
/// as an interval [t0, t1]: everything when the line runs inside the slab parallel to it, an
/// empty interval (t0 > t1) when it runs outside. Callers pass an obstacle's interior
/// ([`Aabb::interior`]), so the per-user loops that call it stay branch-free and vectorised.
#[inline(always)]
fn slab(p: f64, q: f64, lo: f64, hi: f64) -> (f64, f64) {
    let d = q - p;
    if d == 0.0 {
        if p <= lo || p >= hi {
            (f64::INFINITY, f64::NEG_INFINITY)
        } else {
            (f64::NEG_INFINITY, f64::INFINITY)
        }
    } else {
        let (t0, t1) = ((lo - p) / d, (hi - p) / d);
        (t0.min(t1), t0.max(t1))
    }
}

/// The users of a row (`ys` ascending) whose segments from p can meet the open slab (lo, hi)
/// on one axis at a parameter t in `within`: the rest cannot be blocked by it, so a box costs
/// the cells of its shadow on the row, not the whole row (1 000 small boxes over a map).
///
/// y(t) = p + t(y − p) is in (lo, hi) for y in (p + (lo − p)/t, p + (hi − p)/t); as t moves
/// over `within` both ends move monotonically, so the union of these intervals is spanned by
/// the ends' values at t_low and t_high. One more user each side absorbs the rounding of that
/// bound (orders of magnitude below a grid step). A window starting too near t = 0 (the source
/// inside the slabs) bounds nothing useful: the whole row.
fn users_reaching(
    p: f64,
    lo: f64,
    hi: f64,
    within: (f64, f64),
    ys: &[f64],
) -> std::ops::Range<usize> {
    let (t_low, t_high) = within;
    if t_low < 1e-6 {
        return 0..ys.len();
    }
    let end = |edge: f64, t: f64| p + (edge - p) / t;
    let y_min = end(lo, t_low).min(end(lo, t_high));
    let y_max = end(hi, t_low).max(end(hi, t_high));
    let first = ys.partition_point(|&y| y < y_min).saturating_sub(1);
    let last = (ys.partition_point(|&y| y <= y_max) + 1).min(ys.len());
    first..last.max(first)
}

/// `blocked[j] |= ` the segment from p to ys[j] (one axis) meets the open slab (lo, hi) for more
/// than [`GRAZE_T`] of the parameter interval `within`, which the other axes left: a grid row's
/// last slab, vectorised.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512dq+avx512vl",
    "x86_64+avx2+fma",
    "aarch64+neon"
))]
fn slab_row(p: f64, lo: f64, hi: f64, within: (f64, f64), ys: &[f64], blocked: &mut [bool]) {
    for (blocked, &y) in blocked.iter_mut().zip(ys) {
        let (t0, t1) = slab(p, y, lo, hi);
        *blocked |= within.1.min(t1) - within.0.max(t0) > GRAZE_T;
    }
}

/// `blocked[j] |= ` the segment from (s, w) to targets[j] meets the open rectangle `lo`–`hi`
/// of the (s, w) plane for more than [`GRAZE_T`] of `within`: a wall's row, in its frame.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512dq+avx512vl",
    "x86_64+avx2+fma",
    "aarch64+neon"
))]
fn rectangle_row(
    from: [f64; 2],
    lo: [f64; 2],
    hi: [f64; 2],
    within: (f64, f64),
    targets: &[[f64; 2]],
    blocked: &mut [bool],
) {
    for (blocked, to) in blocked.iter_mut().zip(targets) {
        let (s0, s1) = slab(from[0], to[0], lo[0], hi[0]);
        let (w0, w1) = slab(from[1], to[1], lo[1], hi[1]);
        *blocked |= within.1.min(s1).min(w1) - within.0.max(s0).max(w0) > GRAZE_T;
    }
}

/// A row of grid users seen from one source, for [`Obstructions::blocks_row`]: the users are
/// (x, ys[j], z), with `ys` ascending (a grid row's order).
#[derive(Debug, Clone, Copy)]
pub struct RowOfUsers<'a> {
    /// The row's x (m), the same for every user.
    pub x: f64,
    /// Each user's y (m), one per cell of the row.
    pub ys: &'a [f64],
    /// The users' height (m), the same for every user of the row.
    pub z: f64,
}

/// Scratch of [`Obstructions::blocks_row`], kept by the caller from row to row.
#[derive(Debug, Default)]
pub struct RowScratch {
    /// A wall's users in its frame.
    targets: Vec<[f64; 2]>,
    /// What the floor plan's horizon tells of each link.
    settled: Vec<Settled>,
}

/// A pixel coordinate this close (in pixels) to a whole number is taken as that number, so a
/// point on a pixel edge written in metres (x = −7 with 0.05 m pixels is 59.999… pixels from
/// the origin in floating point) is on the edge, exactly as the same point on a box's face is.
/// 1e-9 px is a nanometre at 1 m pixels: far below anything a floor plan resolves.
const SNAP_PX: f64 = 1e-9;

/// An axis-aligned 3D box [lo, hi].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lowest corner (x, y, z) (m).
    pub lo: [f64; 3],
    /// Highest corner (x, y, z) (m); each coordinate ≥ `lo`'s.
    pub hi: [f64; 3],
}

impl Aabb {
    /// The box narrowed by [`GRAZE_M`] at every face: what a link must enter to be blocked.
    /// `None` for a box no thicker than that on some axis, which blocks nothing.
    #[inline]
    fn interior(&self) -> Option<Aabb> {
        let lo = self.lo.map(|v| v + GRAZE_M);
        let hi = self.hi.map(|v| v - GRAZE_M);
        (0..3).all(|k| lo[k] < hi[k]).then_some(Aabb { lo, hi })
    }

    /// True when the segment a→b passes through the open interior, deeper than [`GRAZE_M`]
    /// (slab test with open intervals, so a segment that only grazes a face, edge or corner is
    /// not blocked).
    pub fn blocks(&self, a: &P3, b: &P3) -> bool {
        let Some(inside) = self.interior() else {
            return false;
        };
        let mut t_low = 0.0f64;
        let mut t_high = 1.0f64;
        for axis in 0..3 {
            let (t0, t1) = slab(a[axis], b[axis], inside.lo[axis], inside.hi[axis]);
            t_low = t_low.max(t0);
            t_high = t_high.min(t1);
            if t_high - t_low <= GRAZE_T {
                return false;
            }
        }
        true
    }

    /// [`Aabb::blocks`] from `a` to every user (x, ys[j], z) of a grid row, or-ed into
    /// `blocked`. The x and z slabs do not change along the row, so they are intersected once
    /// (a row they already exclude costs nothing more); per user only the y slab remains. Max
    /// and min are exact, so each answer is bit for bit the per-segment test's.
    fn block_row(&self, a: &P3, x: f64, z: f64, ys: &[f64], blocked: &mut [bool]) {
        let Some(inside) = self.interior() else {
            return;
        };
        let (x0, x1) = slab(a[0], x, inside.lo[0], inside.hi[0]);
        let (z0, z1) = slab(a[2], z, inside.lo[2], inside.hi[2]);
        let (t_low, t_high) = (x0.max(z0).max(0.0), x1.min(z1).min(1.0));
        if t_high - t_low <= GRAZE_T {
            return;
        }
        let reached = users_reaching(a[1], inside.lo[1], inside.hi[1], (t_low, t_high), ys);
        slab_row(
            a[1],
            inside.lo[1],
            inside.hi[1],
            (t_low, t_high),
            &ys[reached.clone()],
            &mut blocked[reached],
        );
    }

    /// The footprint's [x, y] spans.
    fn footprint_bounds(&self) -> [[f64; 2]; 2] {
        [[self.lo[0], self.hi[0]], [self.lo[1], self.hi[1]]]
    }

    /// True when (x, y) lies in or on the footprint.
    fn covers(&self, x: f64, y: f64) -> bool {
        x >= self.lo[0] - ON_BOUNDARY_M
            && x <= self.hi[0] + ON_BOUNDARY_M
            && y >= self.lo[1] - ON_BOUNDARY_M
            && y <= self.hi[1] + ON_BOUNDARY_M
    }

    /// True when the point lies strictly inside.
    fn contains(&self, p: &P3) -> bool {
        (0..3).all(|k| p[k] > self.lo[k] && p[k] < self.hi[k])
    }

    /// True when the footprint's interior and the open square of half-side `h` around (x, y)
    /// overlap by more than [`ON_BOUNDARY_M`] on both axes (touching is not overlapping).
    fn overlaps_square(&self, x: f64, y: f64, h: f64) -> bool {
        overlap(self.lo[0], self.hi[0], x - h, x + h)
            && overlap(self.lo[1], self.hi[1], y - h, y + h)
    }
}

/// True when the intervals [a0, a1] and [b0, b1] overlap by more than [`ON_BOUNDARY_M`].
#[inline]
fn overlap(a0: f64, a1: f64, b0: f64, b1: f64) -> bool {
    a1.min(b1) - a0.max(b0) > ON_BOUNDARY_M
}

/// The cells of `grid` whose squares of half-side `h` can reach the `[x, y]` spans `bounds`,
/// one more each side for rounding: a superset of those a footprint inside `bounds` overlaps.
fn cells_reaching(
    grid: &crate::scenario::Grid,
    bounds: [[f64; 2]; 2],
    h: f64,
) -> impl Iterator<Item = (usize, usize)> {
    let range = |[lo, hi]: [f64; 2], min: f64, n: usize| {
        let first = (((lo - h - min) / grid.resolution_m).floor() as i64 - 1).max(0);
        let last = (((hi + h - min) / grid.resolution_m).ceil() as i64 + 1).min(n as i64 - 1);
        // Empty when the footprint lies off the grid (last < first).
        first as usize..(last + 1).max(first) as usize
    };
    let columns = range(bounds[0], grid.x_min, grid.nx);
    let rows = range(bounds[1], grid.y_min, grid.ny);
    columns.flat_map(move |i| rows.clone().map(move |j| (i, j)))
}

/// A straight wall of any direction: the footprint is the rectangle swept by a segment of
/// thickness `2·half_thickness` centred on the line from `from` along `axis` for `length`, from
/// the floor to `height`. In the wall's own frame (s along the wall, w across it, z up) it is
/// the box [0, length] × [−t/2, t/2] × [0, height], so blockage is the box test in that frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wall {
    from: [f64; 2],
    /// Unit vector from `from` to the far end.
    axis: [f64; 2],
    local: Aabb,
}

impl Wall {
    /// A wall from `from` to `to` (distinct points), `thickness` and `height` positive.
    pub fn new(from: [f64; 2], to: [f64; 2], thickness: f64, height: f64) -> Wall {
        let (dx, dy) = (to[0] - from[0], to[1] - from[1]);
        let length = dx.hypot(dy);
        Wall {
            from,
            axis: [dx / length, dy / length],
            local: Aabb {
                lo: [0.0, -thickness / 2.0, 0.0],
                hi: [length, thickness / 2.0, height],
            },
        }
    }

    /// (s, w, z) of a point in the wall's frame.
    fn local_coordinates(&self, p: &P3) -> P3 {
        let [s, w] = self.local_plane(p[0], p[1]);
        P3::new(s, w, p[2])
    }

    /// (s, w) of a floor point in the wall's frame.
    #[inline(always)]
    fn local_plane(&self, x: f64, y: f64) -> [f64; 2] {
        let (dx, dy) = (x - self.from[0], y - self.from[1]);
        let [ax, ay] = self.axis;
        [dx * ax + dy * ay, dy * ax - dx * ay]
    }

    /// [`Wall::blocks`] from `a` to every user of a row, or-ed into `blocked`: the z slab once,
    /// the wall's two floor axes per user (`targets` is scratch for the users' (s, w)).
    fn block_row(
        &self,
        a: &P3,
        users: RowOfUsers,
        targets: &mut Vec<[f64; 2]>,
        blocked: &mut [bool],
    ) {
        let Some(inside) = self.local.interior() else {
            return;
        };
        let (z0, z1) = slab(a[2], users.z, inside.lo[2], inside.hi[2]);
        let (t_low, t_high) = (z0.max(0.0), z1.min(1.0));
        if t_high - t_low <= GRAZE_T {
            return;
        }
        targets.clear();
        targets.extend(users.ys.iter().map(|&y| self.local_plane(users.x, y)));
        let (lo, hi) = (inside.lo, inside.hi);
        rectangle_row(
            self.local_plane(a[0], a[1]),
            [lo[0], lo[1]],
            [hi[0], hi[1]],
            (t_low, t_high),
            targets,
            blocked,
        );
    }

    fn blocks(&self, a: &P3, b: &P3) -> bool {
        self.local
            .blocks(&self.local_coordinates(a), &self.local_coordinates(b))
    }

    fn covers(&self, x: f64, y: f64) -> bool {
        let p = self.local_coordinates(&P3::new(x, y, 0.0));
        self.local.covers(p[0], p[1])
    }

    fn contains(&self, p: &P3) -> bool {
        self.local.contains(&self.local_coordinates(p))
    }

    /// The height it stands to (m).
    pub fn height(&self) -> f64 {
        self.local.hi[2]
    }

    /// The [x, y] spans of the footprint's bounding box.
    fn footprint_bounds(&self) -> [[f64; 2]; 2] {
        let c = self.corners();
        let span = |k: usize| {
            c.iter()
                .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], p| {
                    [lo.min(p[k]), hi.max(p[k])]
                })
        };
        [span(0), span(1)]
    }

    /// The footprint's corners: (0, −t/2), (L, −t/2), (L, t/2), (0, t/2) in the wall's frame.
    pub(crate) fn corners(&self) -> [[f64; 2]; 4] {
        let [ax, ay] = self.axis;
        // The wall's across-direction (−a_y, a_x): local w = dy·a_x − dx·a_y.
        let corner = |s: f64, t: f64| {
            [
                self.from[0] + s * ax - t * ay,
                self.from[1] + s * ay + t * ax,
            ]
        };
        let (s1, t0, t1) = (self.local.hi[0], self.local.lo[1], self.local.hi[1]);
        [
            corner(0.0, t0),
            corner(s1, t0),
            corner(s1, t1),
            corner(0.0, t1),
        ]
    }

    /// [`Aabb::overlaps_square`] for the wall's rotated footprint: the separating-axis test on
    /// the square's axes (x, y) and the wall's (along, across), each needing an overlap of more
    /// than [`ON_BOUNDARY_M`].
    fn overlaps_square(&self, x: f64, y: f64, h: f64) -> bool {
        let corners = self.corners();
        let span = |k: usize| {
            corners
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
                    (lo.min(c[k]), hi.max(c[k]))
                })
        };
        let ((x0, x1), (y0, y1)) = (span(0), span(1));
        if !overlap(x0, x1, x - h, x + h) || !overlap(y0, y1, y - h, y + h) {
            return false;
        }
        // The square's half-width along either wall axis.
        let reach = h * (self.axis[0].abs() + self.axis[1].abs());
        let [s, w] = self.local_plane(x, y);
        overlap(self.local.lo[0], self.local.hi[0], s - reach, s + reach)
            && overlap(self.local.lo[1], self.local.hi[1], w - reach, w + reach)
    }
}

/// Everything that stands on a floor: what the channel tests links against and what marks grid
/// cells occupied.
#[derive(Debug, Clone, Default)]
pub struct Obstructions {
    /// The scenario's obstacles, standing on the floor.
    pub boxes: Vec<Aabb>,
    /// The scenario's walls, at any angle.
    pub walls: Vec<Wall>,
    /// The decoded floor plan, if any; shared with the scenario's derived copies (placement).
    pub raster: Option<std::sync::Arc<Raster>>,
}

impl Obstructions {
    /// Bytes of the boxes and walls (the raster is shared, see [`Raster`]'s owner).
    pub fn heap_bytes(&self) -> usize {
        self.boxes.capacity() * std::mem::size_of::<Aabb>()
            + self.walls.capacity() * std::mem::size_of::<Wall>()
    }

    /// True when the segment between two points passes through the interior of a box, a wall or
    /// the raster's occupied region.
    pub fn blocks(&self, a: [f64; 3], b: [f64; 3]) -> bool {
        self.blocks_segment(&P3::from(a), &P3::from(b))
    }

    /// [`Obstructions::blocks`] for points the channel model already holds as vectors.
    pub fn blocks_segment(&self, a: &P3, b: &P3) -> bool {
        self.boxes.iter().any(|bx| bx.blocks(a, b))
            || self.walls.iter().any(|w| w.blocks(a, b))
            || self.raster.as_ref().is_some_and(|r| r.blocks(a, b))
    }

    /// `blocked[j]` = [`Obstructions::blocks_segment`] from `source` to each user of a grid
    /// row where `wanted[j]` holds (false elsewhere), bit for bit, a row at a time: what the
    /// gain map's rows test (docs/model.md §2). `horizon` is the floor plan's from `source`
    /// ([`Raster::horizon`]), if any: the links it settles are not walked.
    pub fn blocks_row(
        &self,
        source: &P3,
        horizon: Option<&Horizon>,
        users: RowOfUsers,
        wanted: &[bool],
        scratch: &mut RowScratch,
        blocked: &mut [bool],
    ) {
        blocked.fill(false);
        for bx in &self.boxes {
            bx.block_row(source, users.x, users.z, users.ys, blocked);
        }
        for wall in &self.walls {
            wall.block_row(source, users, &mut scratch.targets, blocked);
        }
        let Some(raster) = &self.raster else {
            for (blocked, &wanted) in blocked.iter_mut().zip(wanted) {
                *blocked &= wanted;
            }
            return;
        };
        let settled = &mut scratch.settled;
        settled.clear();
        settled.resize(users.ys.len(), Settled::Walk);
        if let Some(horizon) = horizon {
            raster.settle_row(horizon, users, settled);
        }
        let mut last = raster::Blocker::default();
        for (j, blocked) in blocked.iter_mut().enumerate() {
            if !wanted[j] {
                *blocked = false;
                continue;
            }
            if *blocked {
                continue;
            }
            *blocked = match settled[j] {
                Settled::Open => false,
                Settled::Shut => true,
                Settled::Walk => {
                    let user = P3::new(users.x, users.ys[j], users.z);
                    raster.blocks_after(source, &user, &mut last)
                }
            };
        }
    }

    /// True when some footprint's interior overlaps the open square of half-side `h` around
    /// (x, y): a grid cell whose square this is is occupied (docs/model.md §1).
    pub fn overlaps_square(&self, x: f64, y: f64, h: f64) -> bool {
        self.boxes.iter().any(|bx| bx.overlaps_square(x, y, h))
            || self.walls.iter().any(|w| w.overlaps_square(x, y, h))
            || self
                .raster
                .as_ref()
                .is_some_and(|r| r.overlaps_square(x, y, h))
    }

    /// Marks `occupied[i·ny + j]` for each cell of `grid` whose square of half-side `h` (the
    /// cell's, or wider for a robot's radius) a box or a wall overlaps
    /// ([`Obstructions::overlaps_square`]), visiting for each only the cells under its
    /// footprint's bounding box: O(cells covered), not O(cells × obstacles).
    pub fn mark_boxes_and_walls(
        &self,
        grid: &crate::scenario::Grid,
        h: f64,
        occupied: &mut [bool],
    ) {
        for bx in &self.boxes {
            for (i, j) in cells_reaching(grid, bx.footprint_bounds(), h) {
                let [x, y] = grid.centre(i, j);
                if bx.overlaps_square(x, y, h) {
                    occupied[grid.index(i, j)] = true;
                }
            }
        }
        for wall in &self.walls {
            for (i, j) in cells_reaching(grid, wall.footprint_bounds(), h) {
                let [x, y] = grid.centre(i, j);
                if wall.overlaps_square(x, y, h) {
                    occupied[grid.index(i, j)] = true;
                }
            }
        }
    }

    /// True when (x, y) lies in or on a footprint.
    pub fn covers(&self, x: f64, y: f64) -> bool {
        self.boxes.iter().any(|bx| bx.covers(x, y))
            || self.walls.iter().any(|w| w.covers(x, y))
            || self.raster.as_ref().is_some_and(|r| r.covers(x, y))
    }

    /// True when a 3D point lies in or on something (closed): what an IRS may hang on.
    pub fn solid_at(&self, p: [f64; 3]) -> bool {
        let below = |h: f64| p[2] >= 0.0 && p[2] <= h + ON_BOUNDARY_M;
        self.boxes
            .iter()
            .any(|bx| bx.covers(p[0], p[1]) && below(bx.hi[2]))
            || self
                .walls
                .iter()
                .any(|w| w.covers(p[0], p[1]) && below(w.local.hi[2]))
            || self
                .raster
                .as_ref()
                .is_some_and(|r| r.covers(p[0], p[1]) && below(r.obstacle_height))
    }

    /// True when a 3D point lies strictly inside something (an AP or a robot cannot be there).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let p = P3::from(p);
        self.boxes.iter().any(|bx| bx.contains(&p))
            || self.walls.iter().any(|w| w.contains(&p))
            || self.raster.as_ref().is_some_and(|r| r.contains(&p))
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use proptest::prelude::*;

    fn p(x: [f64; 3]) -> P3 {
        P3::from(x)
    }

    #[test]
    fn blockage_needs_the_interior_grazing_is_los() {
        let bx = Aabb {
            lo: [0.0, 0.0, 0.0],
            hi: [1.0, 1.0, 1.0],
        };
        let hit = |a: [f64; 3], b: [f64; 3]| bx.blocks(&p(a), &p(b));
        assert!(hit([-1.0, 0.5, 0.5], [2.0, 0.5, 0.5]));
        assert!(
            !hit([-1.0, 0.5, 1.0], [2.0, 0.5, 1.0]),
            "along the top face"
        );
        assert!(!hit([-1.0, 0.0, 0.0], [2.0, 0.0, 0.0]), "along an edge");
        assert!(
            hit([-1.0, -1.0, 0.5], [1.0, 1.0, 0.5]),
            "diagonally through the box"
        );
        assert!(
            !hit([-1.0, 0.0, 0.5], [1.0, 2.0, 0.5]),
            "touching only the vertical edge at (0, 1)"
        );
        assert!(
            !hit([0.5, 0.5, 1.0], [0.5, 5.0, 3.0]),
            "leaving from the top face upwards"
        );
        assert!(hit([0.5, 0.5, 0.5], [5.0, 5.0, 5.0]), "starting inside");
        assert!(!hit([2.0, 2.0, 0.5], [3.0, 3.0, 0.5]), "far away");
    }

    /// A decimal a user types, `units` twentieths of a metre (0.05 m), as the JSON parser reads
    /// it: the double nearest the decimal (an exact integer over 100, correctly rounded).
    fn typed(units: i64) -> f64 {
        (units * 5) as f64 / 100.0
    }

    /// Whether the segment a→b (closed) meets the open box lo–hi, all points given exactly in
    /// twentieths of a metre: the open intervals of t per axis, intersected with [0, 1], compared
    /// as fractions by cross-multiplication.
    fn enters_open_box(a: [i64; 3], b: [i64; 3], lo: [i64; 3], hi: [i64; 3]) -> bool {
        // Bounds as fractions n/d with d > 0: lower bounds strict, [0, 1] closed.
        let (mut lower, mut upper) = ((0i128, 1i128, false), (1i128, 1i128, false));
        let greater = |x: (i128, i128), y: (i128, i128)| x.0 * y.1 > y.0 * x.1;
        for k in 0..3 {
            let d = (b[k] - a[k]) as i128;
            let (l, h) = ((lo[k] - a[k]) as i128, (hi[k] - a[k]) as i128);
            if d == 0 {
                if !(l < 0 && 0 < h) {
                    return false;
                }
                continue;
            }
            let (t0, t1) = if d > 0 {
                ((l, d), (h, d))
            } else {
                ((-h, -d), (-l, -d))
            };
            // t > t0 strictly; a bound equal to the running one becomes strict.
            if greater(t0, (lower.0, lower.1)) || (!greater((lower.0, lower.1), t0) && !lower.2) {
                lower = (t0.0, t0.1, true);
            }
            if greater((upper.0, upper.1), t1) || (!greater(t1, (upper.0, upper.1)) && !upper.2) {
                upper = (t1.0, t1.1, true);
            }
        }
        let (lo_f, hi_f) = ((lower.0, lower.1), (upper.0, upper.1));
        greater(hi_f, lo_f) || (!greater(lo_f, hi_f) && !lower.2 && !upper.2)
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// Grazing is line of sight for the decimals a user types: a box given by its centre
        /// and size, an AP at a typed position and the cell centres of a 0.05, 0.1 or 0.15 m grid
        /// (x_min + i·Δ in floating point, as the map computes them), faces and cells on
        /// multiples of the grid step, so many links run exactly along a face, an edge or through
        /// a corner. Blocked exactly when the exact segment enters the open box.
        #[test]
        fn decimal_links_are_blocked_exactly_when_they_enter_the_box(
            step in prop::sample::select(vec![1i64, 2, 3]),
            centre in (-40i64..40, -40i64..40),
            half in (1i64..12, 1i64..12),
            height in prop::sample::select(vec![20i64, 26, 40]),
            source in (-60i64..60, -60i64..60, prop::sample::select(vec![20i64, 26, 40, 60])),
            x_min in -60i64..-40,
            cell in (0usize..40, 0usize..40),
            antenna in prop::sample::select(vec![20i64, 26]),
        ) {
            // Faces on the grid's lattice: centre and half-size multiples of the step.
            let (c, h) = ([centre.0 * step, centre.1 * step], [half.0 * step, half.1 * step]);
            let b = Aabb {
                lo: [typed(c[0]) - typed(2 * h[0]) / 2.0, typed(c[1]) - typed(2 * h[1]) / 2.0, 0.0],
                hi: [typed(c[0]) + typed(2 * h[0]) / 2.0, typed(c[1]) + typed(2 * h[1]) / 2.0, typed(height)],
            };
            let (x0, dx) = (typed(x_min * step), typed(step));
            let user = [x_min * step + cell.0 as i64 * step, x_min * step + cell.1 as i64 * step, antenna];
            let ap = [source.0 * step, source.1 * step, source.2];
            let exact = enters_open_box(
                ap,
                user,
                [c[0] - h[0], c[1] - h[1], 0],
                [c[0] + h[0], c[1] + h[1], height],
            );
            let a = P3::new(typed(ap[0]), typed(ap[1]), typed(ap[2]));
            let u = P3::new(x0 + cell.0 as f64 * dx, x0 + cell.1 as f64 * dx, typed(antenna));
            prop_assert_eq!(b.blocks(&a, &u), exact, "{:?} → {:?} against {:?}", a, u, b);
            // The row test agrees with the segment test.
            let mut blocked = [false];
            b.block_row(&a, u[0], u[2], &[u[1]], &mut blocked);
            prop_assert_eq!(blocked[0], exact);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// The same for walls at angles whose direction is rational (3-4-5 and 5-12-13
        /// triangles, and the axes), so the exact answer stays in integers: links chosen at
        /// random, along a long face, and along an end face, between typed decimal points on a
        /// 0.05 m lattice and cell centres x_min + i·Δ. The wall's frame turns through cosines
        /// like 0.6 and 0.8, which no double holds, so a link along a face is rounded into it or
        /// out of it unless grazing has a tolerance.
        #[test]
        fn decimal_links_are_blocked_exactly_when_they_enter_a_wall(
            direction in prop::sample::select(vec![(3i64, 4i64), (4, -3), (-5, 12), (12, 5), (1, 0), (0, 1)]),
            k in 1i64..4,
            from in (-20i64..20, -20i64..20),
            thickness in 1i64..6,
            height in prop::sample::select(vec![20i64, 40]),
            mode in 0u8..3,
            offsets in (-30i64..30, -30i64..30),
            source_z in prop::sample::select(vec![20i64, 40, 60]),
            antenna in prop::sample::select(vec![20i64, 26]),
        ) {
            let d = [direction.0 * k, direction.1 * k];
            let norm = ((d[0] * d[0] + d[1] * d[1]) as f64).sqrt().round() as i64;
            let to = [from.0 + d[0], from.1 + d[1]];
            // Twice the half-thickness times |d| is an integer when the thickness is even in
            // units: take thickness 2·t units.
            let th = 2 * thickness;
            // A point on the long face w = +th/2: from + (th/2)·n + m·d/|d|… in lattice terms,
            // p with cross(d, p − from) = (th/2)·|d|: step along d from one such point.
            let on_long_face = |m: i64| -> Option<[i64; 2]> {
                // Solve d0·y − d1·x = thickness·|d| (cross(d, p−from) with p−from = (x, y)).
                let target = thickness * norm;
                for x in -60i64..60 {
                    let rest = target + d[1] * x;
                    if d[0] != 0 && rest % d[0] == 0 {
                        let y = rest / d[0];
                        return Some([from.0 + x + m * direction.0, from.1 + y + m * direction.1]);
                    }
                    if d[0] == 0 {
                        // d = (0, d1): −d1·x = target.
                        if target % d[1] == 0 {
                            let x = -target / d[1];
                            return Some([from.0 + x, from.1 + m]);
                        }
                        return None;
                    }
                }
                None
            };
            let (ap, user) = match mode {
                0 => ([from.0 + offsets.0, from.1 + offsets.1], [from.0 - offsets.1, to[1] + offsets.0]),
                1 => match (on_long_face(offsets.0 % 5), on_long_face(offsets.1 % 5 + 6)) {
                    (Some(a), Some(b)) => (a, b),
                    _ => return Ok(()),
                },
                // Along the end face through `to`: perpendicular to d.
                _ => (
                    [to[0] - direction.1 * (offsets.0 % 4), to[1] + direction.0 * (offsets.0 % 4)],
                    [to[0] - direction.1 * (offsets.1 % 4 + 5), to[1] + direction.0 * (offsets.1 % 4 + 5)],
                ),
            };
            // Exact: the wall's frame scaled by |d| (s·|d| = d·(p − from), w·|d| = cross(d, p − from))
            // and by 2 on both floor axes so the faces are integers.
            let frame = |p: [i64; 2], z: i64| {
                let (x, y) = (p[0] - from.0, p[1] - from.1);
                [2 * (d[0] * x + d[1] * y), 2 * (d[0] * y - d[1] * x), z]
            };
            let exact = enters_open_box(
                frame(ap, source_z),
                frame(user, antenna),
                [0, -th * norm, 0],
                [2 * norm * norm, th * norm, height],
            );
            let wall = Wall::new(
                [typed(from.0), typed(from.1)],
                [typed(to[0]), typed(to[1])],
                typed(th),
                typed(height),
            );
            // The user as a cell centre of a 0.05 m grid whose first centre is at (−3, −3) m.
            let x0 = typed(-60);
            let u = P3::new(
                x0 + (user[0] + 60) as f64 * typed(1),
                x0 + (user[1] + 60) as f64 * typed(1),
                typed(antenna),
            );
            let a = P3::new(typed(ap[0]), typed(ap[1]), typed(source_z));
            prop_assert_eq!(wall.blocks(&a, &u), exact, "mode {}: {:?} → {:?}", mode, a, u);
        }
    }

    /// The example: a 0.3 m box whose face is at x = 5.85, an AP on that face's line,
    /// the cell (5.85, 9) of a 0.05 m grid: the link runs along the face, so it is line of sight.
    #[test]
    fn a_link_along_a_face_at_a_decimal_is_line_of_sight() {
        let b = Aabb {
            lo: [6.0 - 0.3 / 2.0, 7.0 - 2.0 / 2.0, 0.0],
            hi: [6.0 + 0.3 / 2.0, 7.0 + 2.0 / 2.0, 3.0],
        };
        let x = 0.0 + 117.0 * 0.05;
        assert_ne!(x, 5.85, "the cell centre is not the decimal");
        assert!(!b.blocks(&P3::new(5.85, 5.0, 2.0), &P3::new(x, 9.0, 1.0)));
        assert!(b.blocks(&P3::new(5.9, 5.0, 2.0), &P3::new(x + 0.1, 9.0, 1.0)));
    }

    #[test]
    fn an_axis_aligned_wall_is_a_box() {
        let wall = Wall::new([1.0, 2.0], [5.0, 2.0], 0.5, 1.5);
        let bx = Aabb {
            lo: [1.0, 1.75, 0.0],
            hi: [5.0, 2.25, 1.5],
        };
        let segments = [
            ([0.0, 0.0, 1.0], [6.0, 4.0, 1.0]),
            ([3.0, 0.0, 1.0], [3.0, 1.75, 1.0]),
            ([0.0, 1.75, 1.0], [6.0, 1.75, 1.0]),
            ([0.0, 2.0, 2.0], [6.0, 2.0, 1.5]),
            ([0.0, 3.0, 1.0], [2.0, 2.0, 0.0]),
        ];
        for (a, b) in segments {
            assert_eq!(
                wall.blocks(&p(a), &p(b)),
                bx.blocks(&p(a), &p(b)),
                "{a:?}→{b:?}"
            );
        }
        assert!(wall.covers(1.0, 2.25) && !wall.covers(0.9, 2.0));
        // At 45°: a wall from (0,0) to (2,2), 0.2 m thick, crossed by the other diagonal.
        let diagonal = Wall::new([0.0, 0.0], [2.0, 2.0], 0.2, 1.0);
        assert!(diagonal.blocks(&p([0.0, 2.0, 0.5]), &p([2.0, 0.0, 0.5])));
        assert!(
            !diagonal.blocks(&p([0.0, 2.0, 0.5]), &p([0.8, 1.2, 0.5])),
            "stops short"
        );
        assert!(diagonal.covers(1.0, 1.0) && !diagonal.covers(1.0, 0.8));
    }

    /// Boxes on whole pixels, at least one pixel apart (touching boxes differ on purpose: a
    /// segment along their common face is inside the raster's region but in neither box).
    fn separated_boxes(
        cells: &[(usize, usize, usize, usize, u8)],
        width: usize,
        height: usize,
    ) -> Vec<(usize, usize, usize, usize, f64)> {
        let mut taken = vec![false; width * height];
        let mut kept = Vec::new();
        for &(c, r, w, h, z) in cells {
            let (c1, r1) = ((c + w).min(width), (r + h).min(height));
            let clear = (c.saturating_sub(1)..(c1 + 1).min(width)).all(|x| {
                (r.saturating_sub(1)..(r1 + 1).min(height)).all(|y| !taken[y * width + x])
            });
            if clear && c < c1 && r < r1 {
                for x in c..c1 {
                    for y in r..r1 {
                        taken[y * width + x] = true;
                    }
                }
                kept.push((c, r, c1, r1, f64::from(z)));
            }
        }
        kept
    }

    pub(super) fn point() -> impl Strategy<Value = [f64; 3]> {
        (-12.0..12.0f64, -12.0..12.0f64, 0.0..4.0f64).prop_map(|(x, y, z)| [x, y, z])
    }

    /// Random boxes and walls of any direction, no raster.
    pub(super) fn scene() -> impl Strategy<Value = Obstructions> {
        let aabb = (
            -10.0..8.0f64,
            -10.0..8.0f64,
            0.1..4.0f64,
            0.1..4.0f64,
            0.5..3.0f64,
        )
            .prop_map(|(x, y, w, d, h)| Aabb {
                lo: [x, y, 0.0],
                hi: [x + w, y + d, h],
            });
        let wall = (point(), point(), 0.05..0.5f64, 0.5..3.0f64)
            .prop_filter("distinct ends", |(a, b, _, _)| {
                (a[0] - b[0]).hypot(a[1] - b[1]) > 0.1
            })
            .prop_map(|(a, b, t, h)| Wall::new([a[0], a[1]], [b[0], b[1]], t, h));
        (
            proptest::collection::vec(aabb, 0..12),
            proptest::collection::vec(wall, 0..6),
        )
            .prop_map(|(boxes, walls)| Obstructions {
                boxes,
                walls,
                raster: None,
            })
    }

    proptest! {
        /// A row at a time answers what each segment's test answers, bit for bit: random
        /// scenes, sources and rows, rows through the source (a vertical segment) and along
        /// box faces, users level with the source and on the faces.
        #[test]
        fn a_row_of_links_is_blocked_as_each_link_is(
            scene in scene(),
            source in point(),
            row_x in -12.0..12.0f64,
            z in 0.0..4.0f64,
            ys in proptest::collection::vec(-12.0..12.0f64, 30),
        ) {
            let mut xs = vec![row_x, source[0]];
            let mut ys = ys;
            ys.push(source[1]);
            for b in &scene.boxes {
                xs.extend([b.lo[0], b.hi[0]]);
                ys.extend([b.lo[1], b.hi[1]]);
            }
            ys.sort_by(f64::total_cmp);
            let wanted: Vec<bool> = (0..ys.len()).map(|j| j % 7 != 3).collect();
            let (mut scratch, mut blocked) = (RowScratch::default(), vec![true; ys.len()]);
            let source = P3::from(source);
            for x in xs {
                scene.blocks_row(&source, None, RowOfUsers { x, ys: &ys, z }, &wanted, &mut scratch, &mut blocked);
                for (j, &y) in ys.iter().enumerate() {
                    let expected = wanted[j] && scene.blocks_segment(&source, &P3::new(x, y, z));
                    prop_assert_eq!(blocked[j], expected, "{:?} to ({}, {}, {})", source, x, y, z);
                }
            }
        }
    }

    /// A floor plan's rows, with the source's horizon settling what it can, are blocked as each
    /// link is: from the AP and from a surface mounted on a wall pixel's edge, to rows of users
    /// on and off the pixel lattice, at heights below and above the plan's obstacles.
    #[test]
    fn a_floor_plans_rows_are_blocked_as_each_link_is() {
        let (width, height, pixel) = (160, 120, 0.05);
        let mut occupied = vec![false; width * height];
        for r in 0..height {
            for c in 0..width {
                let wall = c >= 150 || r < 4 || (r == 60 && c > 20 && c < 120);
                let rack = (c / 10) % 3 == 1 && (r / 8) % 3 != 0 && c < 140;
                occupied[r * width + c] = wall || rack;
            }
        }
        let raster = Raster::new(width, height, pixel, [-4.0, -3.0], 2.0, &occupied);
        let scene = Obstructions {
            raster: Some(std::sync::Arc::new(raster)),
            ..Obstructions::default()
        };
        let mut settled = 0;
        // The AP in the open; a surface on the east wall's face (x = 150 pixels).
        for source in [
            P3::new(-3.74, -1.1, 1.5),
            P3::new(-4.0 + 150.0 * pixel, -0.2, 1.5),
        ] {
            let horizon = scene.raster.as_ref().unwrap().horizon(&source);
            assert!(horizon.is_some(), "{source:?}");
            for z in [0.5, 1.0, 2.5] {
                for step in 0..45 {
                    let x = -4.0 + step as f64 * 0.17 + if step % 2 == 0 { 0.0 } else { 0.013 };
                    let ys: Vec<f64> = (0..70).map(|j| -3.1 + j as f64 * 0.09).collect();
                    let wanted = vec![true; ys.len()];
                    let (mut scratch, mut blocked) = (RowScratch::default(), vec![false; ys.len()]);
                    let users = RowOfUsers { x, ys: &ys, z };
                    scene.blocks_row(
                        &source,
                        horizon.as_ref(),
                        users,
                        &wanted,
                        &mut scratch,
                        &mut blocked,
                    );
                    for (j, &y) in ys.iter().enumerate() {
                        let user = P3::new(x, y, z);
                        let expected = scene.blocks_segment(&source, &user);
                        assert_eq!(blocked[j], expected, "{source:?} to {user:?}");
                        let raster = scene.raster.as_ref().unwrap();
                        settled +=
                            usize::from(raster.settled(horizon.as_ref().unwrap(), &user).is_some());
                    }
                }
            }
        }
        assert!(settled > 10_000, "{settled} links settled by the horizons");
    }

    /// The occupancy of `grid` as `radiomap::occupancy` computes it, for obstructions without
    /// a scenario.
    fn occupancy(obstructions: &Obstructions, grid: &crate::scenario::Grid) -> Vec<bool> {
        let mut occupied = vec![false; grid.cells()];
        let h = grid.resolution_m / 2.0;
        obstructions.mark_boxes_and_walls(grid, h, &mut occupied);
        if let Some(raster) = &obstructions.raster {
            for (k, cell) in occupied.iter_mut().enumerate() {
                let [x, y] = grid.centre(k / grid.ny, k % grid.ny);
                *cell |= raster.overlaps_square(x, y, h);
            }
        }
        occupied
    }

    /// Every move of the planner's 8-connected graph between two free cells, as segments at
    /// `z` (below every obstacle's top).
    fn free_moves(grid: &crate::scenario::Grid, occupied: &[bool], z: f64) -> Vec<(P3, P3)> {
        let mut moves = Vec::new();
        for i in 0..grid.nx {
            for j in 0..grid.ny {
                for (di, dj) in [(1i64, 0i64), (0, 1), (1, 1), (1, -1)] {
                    let (k, l) = (i as i64 + di, j as i64 + dj);
                    if k >= grid.nx as i64 || l < 0 || l >= grid.ny as i64 {
                        continue;
                    }
                    let (k, l) = (k as usize, l as usize);
                    if occupied[grid.index(i, j)] || occupied[grid.index(k, l)] {
                        continue;
                    }
                    let ([ax, ay], [bx, by]) = (grid.centre(i, j), grid.centre(k, l));
                    moves.push((P3::new(ax, ay, z), P3::new(bx, by, z)));
                }
            }
        }
        moves
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// No move between free cells crosses a box or a wall (the exact segment test), and
        /// marking each obstacle's cells under its bounding box finds exactly the cells whose
        /// squares some obstacle overlaps (a test of every cell against every obstacle), a
        /// superset of the cells whose centre an obstacle covers.
        #[test]
        fn no_move_between_free_cells_crosses_a_box_or_a_wall(
            scene in scene(),
            resolution in prop::sample::select(vec![0.25, 0.4, 0.5, 1.0]),
        ) {
            let n = (20.0 / resolution) as usize + 1;
            let grid = crate::scenario::Grid { nx: n, ny: n, x_min: -10.0, y_min: -10.0, resolution_m: resolution };
            let occupied = occupancy(&scene, &grid);
            for (k, &occ) in occupied.iter().enumerate() {
                let [x, y] = grid.centre(k / grid.ny, k % grid.ny);
                prop_assert_eq!(occ, scene.overlaps_square(x, y, resolution / 2.0), "cell ({}, {})", x, y);
                prop_assert!(occ || !scene.covers(x, y), "a covered centre at ({}, {}) is free", x, y);
            }
            for (a, b) in free_moves(&grid, &occupied, 0.25) {
                prop_assert!(!scene.blocks_segment(&a, &b), "{:?} → {:?} crosses an obstacle", a, b);
            }
        }

        /// With a robot's radius r widening each cell's square, a move between free cells keeps
        /// at least r from every box in both axes: it crosses no box grown by r (the exact
        /// segment test).
        #[test]
        fn a_robots_radius_keeps_its_moves_that_far_from_boxes(
            scene in scene(),
            resolution in prop::sample::select(vec![0.25, 0.5, 1.0]),
            radius in prop::sample::select(vec![0.1, 0.3, 0.45]),
        ) {
            let boxes = Obstructions { walls: vec![], ..scene };
            let n = (20.0 / resolution) as usize + 1;
            let grid = crate::scenario::Grid { nx: n, ny: n, x_min: -10.0, y_min: -10.0, resolution_m: resolution };
            let mut occupied = vec![false; grid.cells()];
            boxes.mark_boxes_and_walls(&grid, resolution / 2.0 + radius, &mut occupied);
            let grown = Obstructions {
                boxes: boxes.boxes.iter().map(|b| Aabb {
                    lo: [b.lo[0] - radius, b.lo[1] - radius, b.lo[2]],
                    hi: [b.hi[0] + radius, b.hi[1] + radius, b.hi[2]],
                }).collect(),
                walls: vec![],
                raster: None,
            };
            for (a, b) in free_moves(&grid, &occupied, 0.25) {
                prop_assert!(!grown.blocks_segment(&a, &b), "{:?} → {:?} comes within {} of a box", a, b, radius);
            }
        }

        /// The same on floor plans: random rasters under grids finer and coarser than their
        /// pixels, aligned with them and not.
        #[test]
        fn no_move_between_free_cells_crosses_an_occupied_pixel(
            width in 4usize..40, height in 4usize..40,
            pixel in prop::sample::select(vec![0.05, 0.1, 0.25, 0.5]),
            offset in prop::sample::select(vec![0.0, 0.013, 0.125]),
            occupied_share in 0.0..0.3f64,
            seed in any::<u64>(),
            resolution in prop::sample::select(vec![0.1, 0.2, 0.25, 0.5]),
        ) {
            let mut state = seed | 1;
            let mut next = || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state };
            let occupied_px: Vec<bool> = (0..width * height)
                .map(|_| (next() % 1000) as f64 / 1000.0 < occupied_share)
                .collect();
            let raster = Raster::new(width, height, pixel, [offset, -offset], 1.0, &occupied_px);
            let scene = Obstructions { boxes: vec![], walls: vec![], raster: Some(std::sync::Arc::new(raster)) };
            let n = ((width.max(height) as f64 * pixel) / resolution) as usize + 2;
            let grid = crate::scenario::Grid { nx: n, ny: n, x_min: 0.0, y_min: -offset, resolution_m: resolution };
            let occupied = occupancy(&scene, &grid);
            for (k, &occ) in occupied.iter().enumerate() {
                let [x, y] = grid.centre(k / grid.ny, k % grid.ny);
                prop_assert!(occ || !scene.covers(x, y), "a covered centre at ({}, {}) is free", x, y);
            }
            for (a, b) in free_moves(&grid, &occupied, 0.5) {
                prop_assert!(!scene.blocks_segment(&a, &b), "{:?} → {:?} crosses an occupied pixel", a, b);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// The raster walk agrees with the box slab test on boxes drawn into a raster: random
        /// rasters (size, origin, pixel size), random pixel-aligned boxes, and segments whose
        /// ends are random or on pixel edges and corners (the degenerate cases).
        #[test]
        fn raster_blockage_equals_the_box_test(
            width in 4usize..24, height in 4usize..24,
            origin in (-8i32..8, -8i32..8),
            resolution in prop::sample::select(vec![0.05, 0.1, 0.25, 0.5, 1.0]),
            cells in prop::collection::vec((0usize..24, 0usize..24, 1usize..6, 1usize..6, 1u8..3), 1..6),
            segments in prop::collection::vec(
                ((0u32..97, 0u32..97, any::<bool>(), 0u32..40), (0u32..97, 0u32..97, any::<bool>(), 0u32..40)),
                1..40),
        ) {
            let origin = [f64::from(origin.0) * 0.5, f64::from(origin.1) * 0.5];
            let boxes: Vec<Aabb> = separated_boxes(&cells, width, height)
                .into_iter()
                .map(|(c0, r0, c1, r1, z)| Aabb {
                    lo: [origin[0] + c0 as f64 * resolution, origin[1] + r0 as f64 * resolution, 0.0],
                    hi: [origin[0] + c1 as f64 * resolution, origin[1] + r1 as f64 * resolution, z],
                })
                .collect();
            // One height for the raster: keep only boxes of the first box's height.
            let h = boxes.first().map_or(1.0, |b| b.hi[2]);
            let boxes: Vec<Aabb> = boxes.into_iter().filter(|b| b.hi[2] == h).collect();
            let pixels: Vec<bool> = (0..width * height)
                .map(|k| {
                    let (c, r) = (k % width, k / width);
                    let centre = [origin[0] + (c as f64 + 0.5) * resolution, origin[1] + (r as f64 + 0.5) * resolution];
                    boxes.iter().any(|b| b.covers(centre[0], centre[1]))
                })
                .collect();
            let raster = Raster::new(width, height, resolution, origin, h, &pixels);
            // Ends on a quarter-pixel lattice (edges and corners included) or jittered off it.
            let point = |(i, j, jitter, z): (u32, u32, bool, u32)| {
                let off = if jitter { 0.1234567 } else { 0.0 };
                P3::new(
                    origin[0] + (f64::from(i) / 4.0 - 0.5 + off) * resolution,
                    origin[1] + (f64::from(j) / 4.0 - 0.5 + off * 0.7) * resolution,
                    f64::from(z) * h / 20.0,
                )
            };
            for (a, b) in segments {
                let (a, b) = (point(a), point(b));
                let by_boxes = boxes.iter().any(|bx| bx.blocks(&a, &b));
                prop_assert_eq!(raster.blocks(&a, &b), by_boxes, "{:?} → {:?}", a, b);
            }
        }
    }
}
