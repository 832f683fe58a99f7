//! The occupancy raster of a ROS floor plan: pixels as columns from the floor, tested like boxes
//! (blockage needs a pixel's open interior, occupancy is closed) by walking the pixels a
//! segment's 2D projection crosses, so a link costs O(pixels crossed) whatever is drawn in the
//! image.

use super::*;

/// An occupancy raster: `width × height` square pixels of side `resolution` (m), the lower-left
/// corner of pixel (0, 0) at `origin`; pixel (c, r) spans [origin_x + c·res, origin_x + (c+1)·res]
/// × [origin_y + r·res, …], so row 0 is the *bottom* of the map (the ROS convention, after the
/// image's rows are flipped). An occupied pixel is a column from the floor to `obstacle_height`.
#[derive(Debug, Clone, PartialEq)]
pub struct Raster {
    /// Columns (pixels along x).
    pub width: usize,
    /// Rows (pixels along y).
    pub height: usize,
    /// Pixel side (m).
    pub resolution: f64,
    /// Lower-left corner of pixel (0, 0): (x, y) (m).
    pub origin: [f64; 2],
    /// Height of an occupied pixel's column (m).
    pub obstacle_height: f64,
    /// Row-major from the bottom row: pixel (c, r) is `occupied[r·width + c]`.
    pub occupied: Vec<bool>,
}

impl Raster {
    /// The map's extent [x_min, x_max] × [y_min, y_max] (m).
    pub fn extent(&self) -> [[f64; 2]; 2] {
        let [ox, oy] = self.origin;
        [
            [ox, ox + self.width as f64 * self.resolution],
            [oy, oy + self.height as f64 * self.resolution],
        ]
    }

    #[inline]
    /// True when pixel (c, r) lies on the map and is occupied.
    pub(crate) fn is_occupied(&self, c: i64, r: i64) -> bool {
        c >= 0
            && r >= 0
            && (c as usize) < self.width
            && (r as usize) < self.height
            && self.occupied[r as usize * self.width + c as usize]
    }

    /// Pixel coordinates (u, v) of a point, each snapped to a whole number within [`SNAP_PX`].
    #[inline]
    fn to_pixels(&self, x: f64, y: f64) -> (f64, f64) {
        let snap = |t: f64| {
            let r = t.round();
            if (t - r).abs() <= SNAP_PX { r } else { t }
        };
        (
            snap((x - self.origin[0]) / self.resolution),
            snap((y - self.origin[1]) / self.resolution),
        )
    }

    /// The pixel indices whose closed extent contains coordinate t: both neighbours on an edge.
    #[inline]
    fn touching(t: f64) -> std::ops::RangeInclusive<i64> {
        let f = t.floor() as i64;
        if t == t.floor() { f - 1..=f } else { f..=f }
    }

    /// True when an occupied pixel's interior overlaps the open square of half-side `h` around
    /// (x, y) (a pixel the square only touches does not count).
    pub fn overlaps_square(&self, x: f64, y: f64, h: f64) -> bool {
        let (u0, v0) = self.to_pixels(x - h, y - h);
        let (u1, v1) = self.to_pixels(x + h, y + h);
        // Pixel c's interior (c, c + 1) meets (u0, u1) iff c < u1 and c + 1 > u0.
        let columns = u0.floor() as i64..=u1.ceil() as i64 - 1;
        let rows = v0.floor() as i64..=v1.ceil() as i64 - 1;
        let (c0, c1) = (
            (*columns.start()).max(0),
            (*columns.end()).min(self.width as i64 - 1),
        );
        let (r0, r1) = (
            (*rows.start()).max(0),
            (*rows.end()).min(self.height as i64 - 1),
        );
        (r0..=r1).any(|r| (c0..=c1).any(|c| self.is_occupied(c, r)))
    }

    /// True when (x, y) lies in or on an occupied pixel.
    pub fn covers(&self, x: f64, y: f64) -> bool {
        let (u, v) = self.to_pixels(x, y);
        Raster::touching(u).any(|c| Raster::touching(v).any(|r| self.is_occupied(c, r)))
    }

    /// True when the 2D point lies in the interior of the occupied region: every pixel whose
    /// closed extent contains it is occupied (inside one pixel, on the edge between two, or on
    /// the corner of four).
    fn interior_at(&self, u: f64, v: f64) -> bool {
        Raster::touching(u).all(|c| Raster::touching(v).all(|r| self.is_occupied(c, r)))
    }

    /// True when the point lies strictly inside an occupied column.
    pub fn contains(&self, p: &P3) -> bool {
        let (u, v) = self.to_pixels(p[0], p[1]);
        p[2] > 0.0 && p[2] < self.obstacle_height && self.interior_at(u, v)
    }

    /// True when the segment a→b passes through the interior of the occupied region (the union
    /// of the occupied columns). The part of the segment below the obstacle height is projected
    /// onto the floor and its pixels are walked column by column along the major axis; a pixel
    /// counts only where the projection crosses its open interior for a positive length, so
    /// grazing an edge or a corner does not block. A projection lying exactly on a pixel edge
    /// is inside the region only where the pixels on both sides are occupied.
    pub fn blocks(&self, a: &P3, b: &P3) -> bool {
        self.trace(a, b).0
    }

    /// The pixel columns [`Raster::blocks`] walks from a to b before it answers: what a
    /// blockage test against the floor plan costs (see `radiomap::cost`).
    pub fn columns_walked(&self, a: &P3, b: &P3) -> usize {
        self.trace(a, b).1
    }

    /// [`Raster::blocks`] and the columns walked to answer it.
    fn trace(&self, a: &P3, b: &P3) -> (bool, usize) {
        // The parameter range where 0 < z(t) < obstacle height.
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        let dz = b[2] - a[2];
        if dz == 0.0 {
            if a[2] <= 0.0 || a[2] >= self.obstacle_height {
                return (false, 0);
            }
        } else {
            let (s0, s1) = ((0.0 - a[2]) / dz, (self.obstacle_height - a[2]) / dz);
            t0 = t0.max(s0.min(s1));
            t1 = t1.min(s0.max(s1));
        }
        if t1 - t0 <= GRAZE_T {
            return (false, 0);
        }
        let (ua, va) = self.to_pixels(a[0], a[1]);
        let (ub, vb) = self.to_pixels(b[0], b[1]);
        let (du, dv) = (ub - ua, vb - va);
        if du == 0.0 && dv == 0.0 {
            // Vertical: a point in plan view.
            return (self.interior_at(ua, va), 1);
        }
        // The clipped part's ends; unclipped ends keep their snapped values exactly.
        let at = |t: f64, s: f64, d: f64, end: f64| {
            if t == 0.0 {
                s
            } else if t == 1.0 {
                end
            } else {
                s + d * t
            }
        };
        let (p, q) = (
            (at(t0, ua, du, ub), at(t0, va, dv, vb)),
            (at(t1, ua, du, ub), at(t1, va, dv, vb)),
        );
        if du.abs() >= dv.abs() {
            self.walk(p, q, |c, r| self.is_occupied(c, r))
        } else {
            self.walk((p.1, p.0), (q.1, q.0), |c, r| self.is_occupied(r, c))
        }
    }

    /// Walks the segment p→q, given as (major, minor) pixel coordinates with |Δmajor| ≥ |Δminor|
    /// and Δmajor ≠ 0, one major-axis column at a time: in each column the segment spans at most
    /// two or three minor-axis pixels. `occupied(major, minor)` looks a pixel up; pixels outside
    /// the raster are free. Answers whether a pixel blocks, and the columns looked at.
    fn walk(
        &self,
        p: (f64, f64),
        q: (f64, f64),
        occupied: impl Fn(i64, i64) -> bool,
    ) -> (bool, usize) {
        let (p, q) = if p.0 <= q.0 { (p, q) } else { (q, p) };
        let slope = (q.1 - p.1) / (q.0 - p.0);
        let minor_at = |m: f64| p.1 + (m - p.0) * slope;
        let limit = self.width.max(self.height) as f64 + 1.0;
        let first = p.0.floor().max(-1.0) as i64;
        let last = (q.0.ceil().min(limit) as i64) - 1;
        for c in first..=last {
            let lo = p.0.max(c as f64);
            let hi = q.0.min(c as f64 + 1.0);
            if hi - lo <= SNAP_PX {
                continue;
            }
            if slope == 0.0 && p.1 == p.1.floor() {
                // Along a pixel edge: inside only where both sides are occupied.
                let r = p.1 as i64;
                if occupied(c, r - 1) && occupied(c, r) {
                    return (true, (c - first + 1) as usize);
                }
                continue;
            }
            let (m0, m1) = {
                let (a, b) = (
                    if lo == p.0 { p.1 } else { minor_at(lo) },
                    if hi == q.0 { q.1 } else { minor_at(hi) },
                );
                if a <= b { (a, b) } else { (b, a) }
            };
            let r_first = (m0 + SNAP_PX).floor() as i64;
            let r_last = (m1 - SNAP_PX).ceil() as i64 - 1;
            if (r_first..=r_last).any(|r| occupied(c, r)) {
                return (true, (c - first + 1) as usize);
            }
        }
        (false, (last - first + 1).max(0) as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: [f64; 3]) -> P3 {
        P3::from(x)
    }

    /// A 4 × 3 raster of 1 m pixels at the origin with the given occupied (column, row) pixels.
    fn raster(occupied: &[(usize, usize)], height: f64) -> Raster {
        let mut r = Raster {
            width: 4,
            height: 3,
            resolution: 1.0,
            origin: [0.0, 0.0],
            obstacle_height: height,
            occupied: vec![false; 12],
        };
        for &(c, row) in occupied {
            r.occupied[row * 4 + c] = true;
        }
        r
    }

    /// The walk's cost is the columns it looks at: all that the segment crosses when nothing
    /// blocks it, up to the first blocking column when something does, none when it passes
    /// above the obstacles.
    #[test]
    fn a_raster_walk_stops_at_its_first_occupied_column() {
        let free = raster(&[], 1.0);
        let walked = |r: &Raster, a: [f64; 3], b: [f64; 3]| r.columns_walked(&p(a), &p(b));
        assert_eq!(walked(&free, [0.0, 1.5, 0.5], [4.0, 1.5, 0.5]), 4);
        assert_eq!(
            walked(&free, [0.5, 0.5, 0.5], [2.5, 1.5, 0.5]),
            3,
            "columns 0, 1, 2"
        );
        let wall = raster(&[(1, 1)], 1.0);
        assert_eq!(walked(&wall, [0.0, 1.5, 0.5], [4.0, 1.5, 0.5]), 2);
        assert_eq!(
            walked(&wall, [4.0, 1.5, 0.5], [0.0, 1.5, 0.5]),
            2,
            "walked from x = 0"
        );
        assert_eq!(
            walked(&wall, [0.0, 1.5, 2.0], [4.0, 1.5, 2.0]),
            0,
            "above the column"
        );
    }

    #[test]
    fn raster_blockage_follows_the_box_rules() {
        let r = raster(&[(1, 1)], 1.0);
        let hit = |a: [f64; 3], b: [f64; 3]| r.blocks(&p(a), &p(b));
        assert!(hit([0.0, 1.5, 0.5], [4.0, 1.5, 0.5]), "through the pixel");
        assert!(hit([2.5, 0.2, 0.5], [1.5, 2.8, 0.5]), "steep, through it");
        assert!(!hit([0.0, 1.5, 1.0], [4.0, 1.5, 1.0]), "along its top");
        assert!(
            hit([0.0, 1.5, 1.5], [4.0, 1.5, 0.0]),
            "descending through it"
        );
        assert!(
            !hit([0.0, 1.5, 2.0], [4.0, 1.5, 0.0]),
            "descending, above it until past it"
        );
        assert!(!hit([0.0, 1.5, 3.0], [4.0, 1.5, 1.2]), "above it");
        assert!(
            !hit([0.0, 1.0, 0.5], [4.0, 1.0, 0.5]),
            "along its lower edge"
        );
        assert!(
            hit([0.0, 0.0, 0.5], [3.0, 3.0, 0.5]),
            "corner to corner through it"
        );
        assert!(
            !hit([0.0, 2.0, 0.5], [2.0, 0.0, 0.5]),
            "touching only its corner (1, 1)"
        );
        assert!(
            !hit([1.0, 3.0, 0.5], [3.0, 1.0, 0.5]),
            "touching only its corner (2, 2)"
        );
        // Two occupied pixels side by side: a segment along their shared edge is inside the
        // region they form.
        let two = raster(&[(1, 1), (1, 0)], 1.0);
        assert!(two.blocks(&p([1.5, -1.0, 0.5]), &p([1.5, 4.0, 0.5])));
        assert!(
            two.blocks(&p([0.0, 1.0, 0.5]), &p([4.0, 1.0, 0.5])),
            "along the seam"
        );
        assert!(
            !r.blocks(&p([0.0, 1.0, 0.5]), &p([4.0, 1.0, 0.5])),
            "seam with one side free"
        );
        // A vertical segment (a point in plan view).
        assert!(r.blocks(&p([1.5, 1.5, 0.2]), &p([1.5, 1.5, 3.0])));
        assert!(
            !r.blocks(&p([1.0, 1.5, 0.2]), &p([1.0, 1.5, 3.0])),
            "on its side"
        );
    }

    #[test]
    fn raster_occupancy_is_closed_and_interior_is_open() {
        let r = raster(&[(1, 1)], 1.0);
        assert!(r.covers(1.5, 1.5));
        assert!(r.covers(1.0, 1.0), "on its corner");
        assert!(r.covers(2.0 + 1e-12, 1.5), "on its edge, up to rounding");
        assert!(!r.covers(0.5, 1.5));
        assert!(r.contains(&p([1.5, 1.5, 0.5])));
        assert!(!r.contains(&p([1.0, 1.5, 0.5])), "on its face");
        assert!(!r.contains(&p([1.5, 1.5, 1.0])), "on its top");
    }
}
