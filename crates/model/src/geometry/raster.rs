//! The occupancy raster of a ROS floor plan: pixels as columns from the floor, tested like boxes
//! (blockage needs a pixel's open interior, occupancy is closed) by walking the pixels a
//! segment's 2D projection crosses, so a link costs at most O(pixels crossed) whatever is drawn
//! in the image.
//!
//! The walk leaps through open floor: each pixel knows its clearance, the chessboard distance
//! to the nearest occupied pixel (a two-pass distance transform when the raster is made), and
//! a segment whose pixels in one column have clearance d cannot meet an occupied pixel in the
//! next d − 2 columns (its slope is at most one pixel per column). The leap only skips pixels
//! proven free, so the answer is the plain walk's, bit for bit (tested against it); what it
//! saves is the columns looked at, a few per aisle instead of one per pixel.
//!
//! A map's rows walk fewer links still: a [`Horizon`] per source tells, direction by
//! direction, within what distance its links are surely free and beyond what distance surely
//! blocked, so only the links near a shadow's edge are walked.

use super::sightlines::pseudo_angle;
use super::*;
use crate::vecmath::ROUNDING_SHIFT;

/// An occupancy raster: `width × height` square pixels of side `resolution` (m), the lower-left
/// corner of pixel (0, 0) at `origin`; pixel (c, r) spans [origin_x + c·res, origin_x + (c+1)·res]
/// × [origin_y + r·res, …], so row 0 is the *bottom* of the map (the ROS convention, after the
/// image's rows are flipped). An occupied pixel is a column from the floor to `obstacle_height`.
/// Made by [`Raster::new`], which works out each pixel's clearance once.
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
    /// Row-major from the bottom row, like `occupied`: the chessboard distance (pixels) from
    /// each pixel to the nearest occupied one, 0 on an occupied pixel, saturated at 255 (every
    /// pixel nearer than that is free; pixels off the map are free).
    clearance: Vec<u8>,
    /// The occupied pixels on the occupied region's edge (one of their eight neighbours free,
    /// or on the map's border), as r·width + c: what a [`Horizon`] is made of.
    edges: Vec<u32>,
}

impl Raster {
    /// A raster of `width × height` pixels; `occupied` is row-major from the bottom row (pixel
    /// (c, r) is `occupied[r·width + c]`) and must hold `width · height` pixels.
    pub fn new(
        width: usize,
        height: usize,
        resolution: f64,
        origin: [f64; 2],
        obstacle_height: f64,
        occupied: &[bool],
    ) -> Raster {
        assert_eq!(occupied.len(), width * height, "one flag per pixel");
        let clearance = clearance(width, height, occupied);
        let edges = (0..width * height)
            .filter(|&k| {
                let (c, r) = (k % width, k / width);
                // Occupied, with a free pixel (clearance ≠ 0) among the 3 × 3 around it.
                clearance[k] == 0
                    && (c == 0
                        || r == 0
                        || c + 1 == width
                        || r + 1 == height
                        || (r - 1..=r + 1).any(|rr| {
                            clearance[rr * width + c - 1..=rr * width + c + 1]
                                .iter()
                                .any(|&d| d != 0)
                        }))
            })
            .map(|k| k as u32)
            .collect();
        Raster {
            width,
            height,
            resolution,
            origin,
            obstacle_height,
            clearance,
            edges,
        }
    }

    /// Every pixel's occupancy, row-major from the bottom row.
    pub fn occupancy(&self) -> Vec<bool> {
        self.clearance.iter().map(|&d| d == 0).collect()
    }

    /// Bytes of the raster's pixels.
    pub fn heap_bytes(&self) -> usize {
        self.clearance.capacity() + 4 * self.edges.capacity()
    }

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
        self.clearance_at(c, r) == 0
    }

    /// Pixel (c, r)'s clearance; 1 off the map (free, but nothing known around it).
    #[inline]
    fn clearance_at(&self, c: i64, r: i64) -> u8 {
        if c >= 0 && r >= 0 && (c as usize) < self.width && (r as usize) < self.height {
            self.clearance[r as usize * self.width + c as usize]
        } else {
            1
        }
    }

    /// Pixel coordinates (u, v) of a point, each snapped to a whole number within [`SNAP_PX`].
    #[inline]
    fn to_pixels(&self, x: f64, y: f64) -> (f64, f64) {
        let snap = |t: f64| {
            // The nearest whole number (inline, unlike `f64::round`); ties do not matter, as
            // only a number within SNAP_PX of it is moved.
            let r = floor(t + 0.5) as f64;
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
        let f = floor(t);
        if f as f64 == t { f - 1..=f } else { f..=f }
    }

    /// True when an occupied pixel's interior overlaps the open square of half-side `h` around
    /// (x, y) (a pixel the square only touches does not count).
    pub fn overlaps_square(&self, x: f64, y: f64, h: f64) -> bool {
        let (u0, v0) = self.to_pixels(x - h, y - h);
        let (u1, v1) = self.to_pixels(x + h, y + h);
        // Pixel c's interior (c, c + 1) meets (u0, u1) iff c < u1 and c + 1 > u0.
        let columns = floor(u0)..=ceil(u1) - 1;
        let rows = floor(v0)..=ceil(v1) - 1;
        let (c0, c1) = (
            (*columns.start()).max(0),
            (*columns.end()).min(self.width as i64 - 1),
        );
        let (r0, r1) = (
            (*rows.start()).max(0),
            (*rows.end()).min(self.height as i64 - 1),
        );
        if c0 > c1 || r0 > r1 {
            return false;
        }
        // Every pixel of the range is within this chessboard distance of the middle one: a
        // middle pixel with more clearance than that answers for all of them (a robot's
        // square is 13 × 13 pixels at 0.3 m on 5 cm pixels; most are far from any wall).
        let (cm, rm) = ((c0 + c1) / 2, (r0 + r1) / 2);
        let reach = (cm - c0).max(c1 - cm).max(rm - r0).max(r1 - rm);
        if reach < i64::from(self.clearance_at(cm, rm)) {
            return false;
        }
        (r0..=r1).any(|r| (c0..=c1).any(|c| self.is_occupied(c, r)))
    }

    /// For each y, the pixel rows [`Raster::overlaps_square`] looks at for a square of
    /// half-side `h` around (·, y): those whose interiors meet (y − h, y + h), clamped to the map
    /// (r0 > r1 when there are none). Every row of a grid (its cells sharing x) has the same.
    pub fn rows_meeting(&self, ys: &[f64], h: f64) -> Vec<(i64, i64)> {
        ys.iter()
            .map(|&y| {
                let (v0, v1) = (self.to_pixels(0.0, y - h).1, self.to_pixels(0.0, y + h).1);
                (floor(v0).max(0), (ceil(v1) - 1).min(self.height as i64 - 1))
            })
            .collect()
    }

    /// [`Raster::overlaps_square`] for the squares of half-side `h` around the centres (x, y) of
    /// a grid row (its cells sharing x), given each square's pixel rows by
    /// [`Raster::rows_meeting`]: sets `out[k]` where the k-th square overlaps an occupied
    /// pixel, leaves it alone elsewhere.
    ///
    /// The occupied pixels of the columns the squares span are counted a pixel row at a time, once
    /// (a row with clearance to spare around its middle pixel counts none unlooked), so a
    /// square costs the difference of two running counts where `overlaps_square` works out
    /// its pixel range and, near a wall, scans it (13 × 13 pixels for a 0.3 m robot on 5 cm
    /// pixels). `counts` is the caller's scratch.
    pub fn mark_overlapping(
        &self,
        x: f64,
        h: f64,
        rows: &[(i64, i64)],
        counts: &mut Vec<u32>,
        out: &mut [bool],
    ) {
        let (u0, u1) = (self.to_pixels(x - h, 0.0).0, self.to_pixels(x + h, 0.0).0);
        let (c0, c1) = (floor(u0).max(0), (ceil(u1) - 1).min(self.width as i64 - 1));
        let meeting = || rows.iter().filter(|(r0, r1)| r0 <= r1);
        let (Some(bottom), Some(top)) = (
            meeting().map(|&(r0, _)| r0).min(),
            meeting().map(|&(_, r1)| r1).max(),
        ) else {
            return;
        };
        if c0 > c1 {
            return;
        }
        let middle = (c0 + c1) / 2;
        let reach = (middle - c0).max(c1 - middle);
        let span = c0 as usize..=c1 as usize;
        // counts[r − bottom] = occupied pixels of columns c0..=c1 in rows bottom..r.
        counts.clear();
        counts.push(0);
        let mut total = 0;
        for r in bottom..=top {
            if reach >= i64::from(self.clearance_at(middle, r)) {
                let row = &self.clearance[r as usize * self.width..][span.clone()];
                total += row.iter().filter(|&&d| d == 0).count() as u32;
            }
            counts.push(total);
        }
        for (cell, &(r0, r1)) in out.iter_mut().zip(rows) {
            if r0 <= r1 && counts[(r1 - bottom) as usize + 1] > counts[(r0 - bottom) as usize] {
                *cell = true;
            }
        }
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
        self.trace(a, b, true, &mut Blocker::default()).0
    }

    /// [`Raster::blocks`] for a run of links from one source to neighbouring users (a grid
    /// row): the few columns around the pixel that blocked the last link are looked at first,
    /// and the whole link is walked only when nothing blocks it there. Links from one source to
    /// neighbouring cells are mostly blocked by the same wall, so they cost a few columns
    /// instead of a walk. The answer is [`Raster::blocks`]'s (tested against it).
    pub fn blocks_after(&self, a: &P3, b: &P3, last: &mut Blocker) -> bool {
        self.trace(a, b, true, last).0
    }

    /// The pixel columns [`Raster::blocks`] looks at from a to b before it answers (not those
    /// it leaps over): what a blockage test against the floor plan costs (see
    /// `radiomap::cost`).
    pub fn columns_walked(&self, a: &P3, b: &P3) -> usize {
        self.trace(a, b, true, &mut Blocker::default()).1
    }

    /// [`Raster::blocks`] and the columns looked at to answer it; `leap` as in
    /// [`Raster::walk`]; the columns around `last` are tried first, and it holds the blocking
    /// pixel after.
    fn trace(&self, a: &P3, b: &P3, leap: bool, last: &mut Blocker) -> (bool, usize) {
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
        let major_is_u = du.abs() >= dv.abs();
        let walk = |window: (i64, i64), leap: bool| {
            if major_is_u {
                self.walk(p, q, window, leap, |c, r| self.clearance_at(c, r))
            } else {
                let (blocked, looked, (m, n)) =
                    self.walk((p.1, p.0), (q.1, q.0), window, leap, |c, r| {
                        self.clearance_at(r, c)
                    });
                (blocked, looked, (n, m))
            }
        };
        // The columns around the last blocking pixel first: a pixel found there blocks, as it
        // would in the whole walk, which looks at the same pixels of those columns.
        let mut tried = 0;
        if let Some((c, r)) = last.0 {
            let at = if major_is_u { c } else { r };
            let (blocked, looked, pixel) = walk((at - BLOCKER_WINDOW, at + BLOCKER_WINDOW), false);
            if blocked {
                last.0 = Some(pixel);
                return (true, looked);
            }
            tried = looked;
        }
        let (blocked, looked, pixel) = walk((i64::MIN, i64::MAX), leap);
        // After a free link the next is likely free too: try nothing first.
        last.0 = blocked.then_some(pixel);
        (blocked, tried + looked)
    }

    /// Walks the segment p→q, given as (major, minor) pixel coordinates with |Δmajor| ≥ |Δminor|
    /// and Δmajor ≠ 0, one major-axis column at a time: in each column the segment spans at most
    /// two or three minor-axis pixels. `clearance(major, minor)` looks a pixel's clearance up
    /// (0: occupied). Answers whether a pixel blocks, the columns looked at, and the blocking
    /// pixel as (major, minor) when one does.
    ///
    /// Only the columns in `window` (inclusive) are looked at.
    ///
    /// With `leap`, a column whose pixels are all free at clearance ≥ d sends the walk d − 1
    /// columns on: in column c + j the segment's minor coordinate is within j + 1 of its range
    /// in column c (|slope| ≤ 1, and a column is one pixel wide), so every pixel it crosses
    /// there is within chessboard distance j + 1 of a pixel just looked at, hence free while
    /// j + 1 < d. Without it, every column is looked at: the reference the tests hold the
    /// leaps to.
    fn walk(
        &self,
        p: (f64, f64),
        q: (f64, f64),
        window: (i64, i64),
        leap: bool,
        clearance: impl Fn(i64, i64) -> u8,
    ) -> (bool, usize, (i64, i64)) {
        let (p, q) = if p.0 <= q.0 { (p, q) } else { (q, p) };
        let slope = (q.1 - p.1) / (q.0 - p.0);
        let minor_at = |m: f64| p.1 + (m - p.0) * slope;
        let limit = self.width.max(self.height) as f64 + 1.0;
        // A column holding no more than SNAP_PX of the segment is not looked at; only an end
        // column can (the others hold a whole pixel of it), so the ends are trimmed here and
        // the loop has no skipping path (which the compiler would vectorise into a scan
        // costing more than the leaps save).
        let thin = |c: i64| q.0.min(c as f64 + 1.0) - p.0.max(c as f64) <= SNAP_PX;
        let mut first = floor(p.0.max(-1.0)).max(window.0);
        let mut last = (ceil(q.0.min(limit)) - 1).min(window.1);
        if first <= last && thin(first) {
            first += 1;
        }
        if first <= last && thin(last) {
            last -= 1;
        }
        let along_edge = slope == 0.0 && p.1 == floor(p.1) as f64;
        let (mut c, mut looked) = (first, 0);
        while c <= last {
            let lo = p.0.max(c as f64);
            let hi = q.0.min(c as f64 + 1.0);
            looked += 1;
            let least = if along_edge {
                // Along a pixel edge: inside only where both sides are occupied.
                let r = p.1 as i64;
                let (below, above) = (clearance(c, r - 1), clearance(c, r));
                if below == 0 && above == 0 {
                    return (true, looked, (c, r));
                }
                below.max(1).min(above.max(1))
            } else {
                let (m0, m1) = {
                    let (a, b) = (
                        if lo == p.0 { p.1 } else { minor_at(lo) },
                        if hi == q.0 { q.1 } else { minor_at(hi) },
                    );
                    if a <= b { (a, b) } else { (b, a) }
                };
                // The rows crossed: none, one or two, since the span is at most one pixel
                // (|slope| ≤ 1). Both candidates are read and the unused one masked, so the
                // loop has no branch on how many there are.
                let r_first = floor(m0 + SNAP_PX);
                let r_last = ceil(m1 - SNAP_PX) - 1;
                let (d0, d1) = (clearance(c, r_first), clearance(c, r_first + 1));
                let d1 = if r_last > r_first { d1 } else { u8::MAX };
                // A column whose span rounds to no pixel vouches for none around it.
                let least = if r_last >= r_first { d0.min(d1) } else { 1 };
                if least == 0 {
                    return (true, looked, (c, r_first + i64::from(d0 != 0)));
                }
                least
            };
            c += if leap { i64::from(least.max(2)) - 1 } else { 1 };
        }
        (false, looked, (0, 0))
    }
}

/// Direction bins of a [`Horizon`] over the full turn (of the pseudo-angle, as
/// [`super::sightlines`] sorts directions). At 16 384 a bin is 0.022°: 8 mm wide 20 m from the
/// source, so only the users within a bin or two of a shadow's edge still need the walk.
/// 256 kB a source.
const HORIZON_BINS: usize = 1 << 14;

/// How deep inside an occupied pixel (pixels, from each side) every direction of a bin must
/// pass for [`Horizon`] to call the bin shut there: far above rounding, so the walk surely
/// finds that pixel (in its column the segment's rows are read with a margin of [`SNAP_PX`]).
const SHUT_DEPTH_PX: f64 = 1e-3;

/// What the floor plan surely does to the links from one source, direction by direction:
/// within a distance nothing blocks them, beyond another an occupied pixel surely does. Per
/// bin (widened by one each side, so that rounding in an angle never drops a pixel):
/// - `open`: the least distance (pixels, squared) from the source to an occupied pixel whose
///   square meets the bin's directions. A shorter link meets no occupied pixel, so
///   [`Raster::blocks`] would walk it only to answer "free". Only the pixels on the occupied
///   region's edge are listed (one of their eight neighbours free, or on the map's border): a
///   segment from a free point that meets an occupied pixel meets one of those first, no
///   farther away.
/// - `shut`: the least distance (squared) from the source to the far corner of an occupied
///   pixel that every direction of the bin crosses at least [`SHUT_DEPTH_PX`] inside. A longer
///   link whose every point is below the obstacles' height crosses that pixel's interior, and
///   the walk finds it.
///
/// Links in between, near a shadow's edge or over the obstacles, are walked
/// ([`Raster::settle_row`]). A source inside the occupied region has no horizon; one on its edge
/// (a surface mounted on a wall) has one, the directions into the pixels it touches left to
/// the walk.
#[derive(Debug, Clone)]
pub struct Horizon {
    /// The source in pixel coordinates, as [`Raster::trace`] sees it (snapped).
    source: (f64, f64),
    /// Whether the source is strictly below the obstacles' top: only then may a bin shut.
    source_below: bool,
    /// Per bin, `open` and `shut` side by side: a link reads both from one cache line. A
    /// fixed length, so that an index clamped to it needs no bounds check.
    bins: Box<[[f64; 2]; HORIZON_BINS]>,
}

impl Horizon {
    /// Bytes of a horizon's bins.
    pub const HEAP_BYTES: usize = 2 * HORIZON_BINS * std::mem::size_of::<f64>();

    /// Bytes of the bins.
    pub fn heap_bytes(&self) -> usize {
        std::mem::size_of_val(&*self.bins)
    }
}

/// The bin of a pseudo-angle in [0, 4) (or of one a little outside, wrapped by the caller).
/// The inline [`floor`]: `f64::floor` is a libm call, once per link of a map's rows.
#[inline]
fn horizon_bin(angle: f64) -> i64 {
    floor(angle * (HORIZON_BINS as f64 / 4.0))
}

/// Lowers side `k` (open or shut) of bins `first..=last` (wrapped past the last bin, at most a
/// turn) to `value`: as at most two runs of consecutive bins, by a compare and a select (no
/// index wrapped per bin, no NaN test; the values are finite), which is most of a horizon's
/// cost (a pixel near the source spans thousands of bins).
fn lower_bins(bins: &mut [[f64; 2]], first: i64, last: i64, k: usize, value: f64) {
    let count = HORIZON_BINS as i64;
    debug_assert!(last - first < count, "at most a turn");
    if last < first {
        return;
    }
    let start = first.rem_euclid(count) as usize;
    let end = start + (last - first) as usize; // inclusive, may pass the last bin
    let (head, wrapped) = if end < HORIZON_BINS {
        (start..=end, 0..0)
    } else {
        (start..=HORIZON_BINS - 1, 0..end + 1 - HORIZON_BINS)
    };
    let lower = |run: &mut [[f64; 2]]| {
        for bin in run {
            bin[k] = if value < bin[k] { value } else { bin[k] };
        }
    };
    lower(&mut bins[head]);
    lower(&mut bins[wrapped]);
}

/// A distance (squared) within a margin far above rounding: `a` surely below `b`.
fn surely_below(a: f64, b: f64) -> bool {
    a * (1.0 + 1e-9) + 1e-6 < b
}

impl Raster {
    /// The [`Horizon`] of the floor plan from `source` (only its x and y matter); `None` when
    /// the source lies inside the occupied region (every pixel whose closed square holds it is
    /// occupied). A source on the region's edge, as a surface mounted on a wall is, has one.
    pub fn horizon(&self, source: &P3) -> Option<Horizon> {
        let (su, sv) = self.to_pixels(source[0], source[1]);
        if self.interior_at(su, sv) {
            return None;
        }
        // [open, shut] per bin.
        let mut bins = vec![[f64::INFINITY; 2]; HORIZON_BINS];
        // The cone of directions from the source to the square [x0, x1] × [y0, y1] (which
        // does not hold the source in its interior, so the cone is at most a half turn wide,
        // when the source is on an edge): its ends as pseudo-angles, measured from the
        // centre's direction so that a cone across the +x axis does not wrap. A corner at the
        // source has no direction; the others span the cone.
        let cone = |x0: f64, x1: f64, y0: f64, y1: f64| {
            let centre = pseudo_angle((x0 + x1) / 2.0 - su, (y0 + y1) / 2.0 - sv);
            let (mut lo, mut hi) = (0.0f64, 0.0f64);
            for (cx, cy) in [(x0, y0), (x1, y0), (x0, y1), (x1, y1)] {
                if cx == su && cy == sv {
                    continue;
                }
                // Wrapped into [−2, 2]: a − 4·round(a/4) for |a| < 4, by selects (`round`
                // is a libm call, eight an edge pixel).
                let a = pseudo_angle(cx - su, cy - sv) - centre;
                let a = if a >= 2.0 {
                    a - 4.0
                } else if a <= -2.0 {
                    a + 4.0
                } else {
                    a
                };
                (lo, hi) = (lo.min(a), hi.max(a));
            }
            (centre + lo, centre + hi)
        };
        for &k in &self.edges {
            let (x0, y0) = (
                (k as usize % self.width) as f64,
                (k as usize / self.width) as f64,
            );
            // The least distance from the source to the pixel's closed square.
            let dx = (x0 - su).max(su - (x0 + 1.0)).max(0.0);
            let dy = (y0 - sv).max(sv - (y0 + 1.0)).max(0.0);
            let near = dx * dx + dy * dy;
            let (lo, hi) = cone(x0, x0 + 1.0, y0, y0 + 1.0);
            lower_bins(&mut bins, horizon_bin(lo) - 1, horizon_bin(hi) + 1, 0, near);
            // The bins whose every direction (widened by a bin each side) crosses the pixel
            // shrunk by SHUT_DEPTH_PX: those lying inside its cone, a bin in. (Edge pixels
            // only: deeper ones lie behind them, and any occupied pixel may vouch.)
            let d = SHUT_DEPTH_PX;
            let (lo, hi) = cone(x0 + d, x0 + 1.0 - d, y0 + d, y0 + 1.0 - d);
            let (first, last) = (horizon_bin(lo) + 2, horizon_bin(hi) - 2);
            if first <= last {
                // The far corner: the farther side along each axis.
                let far_x = (x0 - su).abs().max((x0 + 1.0 - su).abs());
                let far_y = (y0 - sv).abs().max((y0 + 1.0 - sv).abs());
                let far = far_x * far_x + far_y * far_y;
                lower_bins(&mut bins, first, last, 1, far);
            }
        }
        Some(Horizon {
            source: (su, sv),
            source_below: self.below_obstacles(source[2]),
            bins: bins
                .into_boxed_slice()
                .try_into()
                .expect("HORIZON_BINS bins"),
        })
    }

    /// Whether height `z` lies strictly between the floor and the obstacles' top.
    fn below_obstacles(&self, z: f64) -> bool {
        z > 0.0 && z < self.obstacle_height
    }

    /// What the horizon tells of the links from its source to a row of users (their x and
    /// height shared): `out[j]` is [`Settled::Open`] for a link surely in the open,
    /// [`Settled::Shut`] for one surely through an occupied pixel (what [`Raster::blocks`]
    /// would answer), and [`Settled::Walk`] where only the walk can tell. A whole row at once,
    /// without a branch, so that the compiler vectorises it: one link costs a few
    /// nanoseconds, where asking link by link cost ≈ 35 (two divisions, a call and a
    /// dependent load each, 40 % of a floor plan's gain map).
    pub fn settle_row(&self, horizon: &Horizon, users: RowOfUsers, out: &mut [Settled]) {
        assert_eq!(out.len(), users.ys.len(), "one answer per user");
        let (u, _) = self.to_pixels(users.x, self.origin[1]);
        let row = RowFrame {
            du: u - horizon.source.0,
            source_v: horizon.source.1,
            origin_y: self.origin[1],
            resolution: self.resolution,
            // Shut only where the whole link is walked: both ends strictly below the obstacles.
            may_shut: horizon.source_below && self.below_obstacles(users.z),
        };
        settle_links(&horizon.bins, row, users.ys, out);
    }

    /// [`Raster::settle_row`] for one link from the horizon's source to `b`: `Some(blocked)`
    /// where the horizon settles it.
    #[cfg(test)]
    pub(crate) fn settled(&self, horizon: &Horizon, b: &P3) -> Option<bool> {
        let mut out = [Settled::Walk];
        let users = RowOfUsers {
            x: b[0],
            ys: &[b[1]],
            z: b[2],
        };
        self.settle_row(horizon, users, &mut out);
        match out[0] {
            Settled::Open => Some(false),
            Settled::Shut => Some(true),
            Settled::Walk => None,
        }
    }
}

/// What a [`Horizon`] tells of one link ([`Raster::settle_row`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum Settled {
    /// Surely free: shorter than any occupied pixel in its direction.
    Open,
    /// Surely blocked: through an occupied pixel below the obstacles' top.
    Shut,
    /// Near a shadow's edge or over the obstacles: walk it.
    #[default]
    Walk,
}

/// What the links of a grid row share, in pixels ([`Raster::settle_row`]).
#[derive(Debug, Clone, Copy)]
struct RowFrame {
    /// The row's u (snapped) less the source's.
    du: f64,
    /// The source's v (snapped).
    source_v: f64,
    origin_y: f64,
    resolution: f64,
    /// Whether a link may be settled shut (both ends below the obstacles' top).
    may_shut: bool,
}

/// [`Raster::settle_row`]'s loop: per user the pixel coordinate as [`Raster::to_pixels`] snaps
/// it (the floor by the rounding shift, as a double), the pseudo-angle's bin and the bin's two
/// distances, all by selects rather than branches.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512dq+avx512vl",
    "x86_64+avx2+fma",
    "aarch64+neon"
))]
fn settle_links(bins: &[[f64; 2]; HORIZON_BINS], row: RowFrame, ys: &[f64], out: &mut [Settled]) {
    let du = row.du;
    for (out, &y) in out.iter_mut().zip(ys) {
        let t = (y - row.origin_y) / row.resolution;
        let r = floor_f64(t + 0.5);
        let v = if (t - r).abs() <= SNAP_PX { r } else { t };
        let dv = v - row.source_v;
        let d2 = du * du + dv * dv;
        let p = dv / (du.abs() + dv.abs());
        // pseudo_angle's branches as selects.
        let angle = if du >= 0.0 {
            if dv >= 0.0 { p } else { 4.0 + p }
        } else {
            2.0 - p
        };
        let bin = horizon_bin(angle).clamp(0, HORIZON_BINS as i64 - 1) as usize;
        let [open, shut] = bins[bin];
        let at_source = du == 0.0 && dv == 0.0;
        let is_open = surely_below(d2, open);
        let is_shut = row.may_shut && surely_below(shut, d2);
        *out = if at_source {
            Settled::Walk
        } else if is_open {
            Settled::Open
        } else if is_shut {
            Settled::Shut
        } else {
            Settled::Walk
        };
    }
}

/// ⌊t⌋ as a double, by the rounding shift as [`floor`] (equal to `floor(t) as f64`), without
/// leaving the floating-point registers: what a vectorised loop wants.
#[inline]
fn floor_f64(t: f64) -> f64 {
    let (t, _, rounded) = nearest(t);
    if rounded > t { rounded - 1.0 } else { rounded }
}

/// The pixel a link from the same source was last blocked by, for [`Raster::blocks_after`].
#[derive(Debug, Clone, Copy, Default)]
pub struct Blocker(Option<(i64, i64)>);

/// Columns on each side of the last blocking pixel's that [`Raster::blocks_after`] looks at
/// before walking the whole link. Timed on the warehouse plan at 5 cm (the links from its AP
/// and from its IRS to every free cell, a row at a time, best of five): 210 and 370 ns a link
/// with 2, against 236 and 390 ns with the blocking column alone and 234 and 334 ns with 4.
const BLOCKER_WINDOW: i64 = 2;

/// The chessboard distance from each pixel to the nearest occupied pixel, saturated at 255,
/// by the two-pass transform (Rosenfeld and Pfaltz): a forward pass takes the least of the
/// four neighbours already visited plus one, a backward pass the other four; off the map
/// counts as free and far.
fn clearance(width: usize, height: usize, occupied: &[bool]) -> Vec<u8> {
    let mut d: Vec<u8> = occupied
        .iter()
        .map(|&o| if o { 0 } else { u8::MAX })
        .collect();
    let at = |d: &[u8], c: usize, r: usize| d[r * width + c];
    for r in 0..height {
        for c in 0..width {
            let k = r * width + c;
            if d[k] == 0 {
                continue;
            }
            let mut m = if c > 0 { at(&d, c - 1, r) } else { u8::MAX };
            if r > 0 {
                m = m.min(at(&d, c, r - 1));
                if c > 0 {
                    m = m.min(at(&d, c - 1, r - 1));
                }
                if c + 1 < width {
                    m = m.min(at(&d, c + 1, r - 1));
                }
            }
            d[k] = d[k].min(m.saturating_add(1));
        }
    }
    for r in (0..height).rev() {
        for c in (0..width).rev() {
            let k = r * width + c;
            if d[k] == 0 {
                continue;
            }
            let mut m = if c + 1 < width {
                at(&d, c + 1, r)
            } else {
                u8::MAX
            };
            if r + 1 < height {
                m = m.min(at(&d, c, r + 1));
                if c + 1 < width {
                    m = m.min(at(&d, c + 1, r + 1));
                }
                if c > 0 {
                    m = m.min(at(&d, c - 1, r + 1));
                }
            }
            d[k] = d[k].min(m.saturating_add(1));
        }
    }
    d
}

/// ⌊t⌋ as an integer, inline: `f64::floor` is a libm call on the baseline x86-64 target, and
/// the walk takes several per column. Adding 1.5·2⁵² rounds t to the nearest integer r, which
/// is then the sum's low mantissa bits; r − 1 where r > t. A cast (`t as i64`) would instead
/// pay for Rust's saturation: a NaN test and a range test on every conversion. t is first
/// clamped to ±2⁵⁰ (NaN to −2⁵⁰), where the shift is exact: a point that far off the map
/// (a floor plan of tiny pixels far from the room) stays off it, and the `± 1`s the callers
/// add cannot overflow.
#[inline]
fn floor(t: f64) -> i64 {
    let (t, nearest, rounded) = nearest(t);
    nearest - i64::from(rounded > t)
}

/// ⌈t⌉ as an integer, inline (see [`floor`]).
#[inline]
fn ceil(t: f64) -> i64 {
    let (t, nearest, rounded) = nearest(t);
    nearest + i64::from(rounded < t)
}

/// t clamped to ±2⁵⁰, the integer nearest it, and that integer as a double (see [`floor`]).
#[inline]
fn nearest(t: f64) -> (f64, i64, f64) {
    const LIMIT: f64 = (1u64 << 50) as f64;
    // Not `clamp`, which keeps a NaN: `max` turns it into −2⁵⁰.
    #[allow(clippy::manual_clamp)]
    let t = t.max(-LIMIT).min(LIMIT);
    let shifted = t + ROUNDING_SHIFT;
    let nearest = shifted.to_bits() as i64 - ROUNDING_SHIFT.to_bits() as i64;
    (t, nearest, shifted - ROUNDING_SHIFT)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points 10¹⁶ pixels off a plan (tiny pixels, the room far from them) are answered at
    /// once: free, nothing overlapped, no walk of 10¹⁶ columns and no overflow.
    #[test]
    fn points_far_off_a_plan_of_tiny_pixels_are_answered_at_once() {
        let r = Raster::new(1, 1, 1e-19, [0.0, 0.0], 2.0, &[true]);
        let (a, b) = (P3::new(-0.001, -0.001, 0.5), P3::new(-0.002, -0.0015, 0.5));
        assert!(!r.blocks(&a, &b));
        assert!(!r.blocks(&b, &P3::new(0.002, 0.003, 1.0)));
        assert!(!r.overlaps_square(-0.001, -0.001, 0.0005));
        let rows = r.rows_meeting(&[-0.001, 0.001], 0.0005);
        let mut marked = [false; 2];
        r.mark_overlapping(-0.001, 0.0005, &rows, &mut Vec::new(), &mut marked);
        assert_eq!(marked, [false, false]);
    }

    /// The inline floor and ceiling agree with libm's on integers, halves, their neighbours
    /// one ulp away, negatives and values up to 2⁵⁰.
    #[test]
    fn inline_floor_and_ceil_agree_with_libm() {
        let mut values = vec![0.0, -0.0, 1e-300, -1e-300, 2f64.powi(50), -(2f64.powi(50))];
        for k in -300..300 {
            let t = f64::from(k) / 4.0;
            values.extend([t, t.next_up(), t.next_down()]);
        }
        let mut x = 0.123_456_789f64;
        for _ in 0..10_000 {
            x = (x * 9_301.0 + 0.497).fract();
            values.extend([x * 1e6 - 5e5, x * 100.0 - 50.0]);
        }
        for t in values {
            assert_eq!(floor(t), t.floor() as i64, "floor({t})");
            assert_eq!(ceil(t), t.ceil() as i64, "ceil({t})");
        }
        // Beyond ±2⁵⁰ (and NaN) the clamp's ends, far off any map, with room for the ± 1s.
        let limit = 1i64 << 50;
        for (t, end) in [
            (1e16, limit),
            (-1e16, -limit),
            (-6.8e15, -limit),
            (f64::NAN, -limit),
        ] {
            assert_eq!((floor(t), ceil(t)), (end, end), "{t}");
        }
    }

    fn p(x: [f64; 3]) -> P3 {
        P3::from(x)
    }

    /// A 4 × 3 raster of 1 m pixels at the origin with the given occupied (column, row) pixels.
    fn raster(occupied: &[(usize, usize)], height: f64) -> Raster {
        let mut pixels = vec![false; 12];
        for &(c, row) in occupied {
            pixels[row * 4 + c] = true;
        }
        Raster::new(4, 3, 1.0, [0.0, 0.0], height, &pixels)
    }

    /// The walk's cost is the columns it looks at: without leaps, all that the segment crosses
    /// when nothing blocks it, up to the first blocking column when something does, none when
    /// it passes above the obstacles; with them, one per stretch of open floor.
    #[test]
    fn a_raster_walk_stops_at_its_first_occupied_column() {
        let free = raster(&[], 1.0);
        let plain = |r: &Raster, a: [f64; 3], b: [f64; 3]| {
            r.trace(&p(a), &p(b), false, &mut Blocker::default()).1
        };
        assert_eq!(plain(&free, [0.0, 1.5, 0.5], [4.0, 1.5, 0.5]), 4);
        assert_eq!(
            plain(&free, [0.5, 0.5, 0.5], [2.5, 1.5, 0.5]),
            3,
            "columns 0, 1, 2"
        );
        let wall = raster(&[(1, 1)], 1.0);
        assert_eq!(plain(&wall, [0.0, 1.5, 0.5], [4.0, 1.5, 0.5]), 2);
        assert_eq!(
            plain(&wall, [4.0, 1.5, 0.5], [0.0, 1.5, 0.5]),
            2,
            "walked from x = 0"
        );
        assert_eq!(
            plain(&wall, [0.0, 1.5, 2.0], [4.0, 1.5, 2.0]),
            0,
            "above the column"
        );
        let walked = |r: &Raster, a: [f64; 3], b: [f64; 3]| r.columns_walked(&p(a), &p(b));
        assert_eq!(
            walked(&free, [0.0, 1.5, 0.5], [4.0, 1.5, 0.5]),
            1,
            "one leap"
        );
        assert_eq!(
            walked(&wall, [0.0, 1.5, 0.5], [4.0, 1.5, 0.5]),
            2,
            "no room to leap"
        );
    }

    /// Chessboard distances by brute force: the least max(|Δc|, |Δr|) to an occupied pixel.
    fn brute_clearance(width: usize, height: usize, occupied: &[bool]) -> Vec<u8> {
        (0..width * height)
            .map(|k| {
                let (c, r) = ((k % width) as i64, (k / width) as i64);
                (0..width * height)
                    .filter(|&o| occupied[o])
                    .map(|o| {
                        let (oc, or) = ((o % width) as i64, (o / width) as i64);
                        (c - oc).abs().max((r - or).abs())
                    })
                    .min()
                    .map_or(u8::MAX, |d| d.min(255) as u8)
            })
            .collect()
    }

    /// A raster from a seed: `share` of its pixels occupied, in runs along rows (walls) and
    /// scattered (clutter).
    fn seeded(width: usize, height: usize, share: f64, seed: u64, pixel: f64) -> Raster {
        let mut state = seed | 1;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let mut occupied = vec![false; width * height];
        let mut k = 0;
        while k < occupied.len() {
            if (next() % 10_000) as f64 / 10_000.0 < share {
                let run = 1 + (next() % 6) as usize;
                occupied[k..(k + run).min(width * height)].fill(true);
                k += run;
            }
            k += 1;
        }
        Raster::new(width, height, pixel, [-1.3, 0.7], 2.0, &occupied)
    }

    use proptest::prelude::*;

    /// The reference: the walk that looks at every column, with no pixel tried first.
    fn plain(r: &Raster, a: &P3, b: &P3) -> bool {
        r.trace(a, b, false, &mut Blocker::default()).0
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn clearance_is_the_chessboard_distance_to_the_nearest_occupied_pixel(
            width in 1usize..40, height in 1usize..40,
            share in prop::sample::select(vec![0.0, 0.002, 0.02, 0.2]),
            seed in any::<u64>(),
        ) {
            let r = seeded(width, height, share, seed, 0.1);
            prop_assert_eq!(&r.clearance, &brute_clearance(width, height, &r.occupancy()));
        }

        /// The leaping walk answers as the plain walk does, on rasters from empty to cluttered,
        /// with segment ends random, on the pixel lattice (edges, corners, along an edge),
        /// beyond the map, and at heights around the obstacles' top; and it never looks at more
        /// columns.
        #[test]
        fn leaps_answer_as_the_plain_walk(
            width in 8usize..300, height in 8usize..300,
            share in prop::sample::select(vec![0.0, 0.0005, 0.003, 0.02, 0.1]),
            seed in any::<u64>(),
            pixel in prop::sample::select(vec![0.05, 0.1, 0.25]),
            ends in prop::collection::vec(
                ((-8i32..1210, -8i32..1210, 0u8..4), (-8i32..1210, -8i32..1210, 0u8..4), 0u8..5, 0u8..5),
                1..60),
        ) {
            let r = seeded(width, height, share, seed, pixel);
            let plain = |a: &P3, b: &P3| plain(&r, a, b);
            let [ox, oy] = r.origin;
            // Quarter-pixel lattice points, some nudged off it; z below, at and above the top.
            let at = |(i, j, off): (i32, i32, u8), z: u8| {
                let nudge = f64::from(off) * 0.137;
                P3::new(
                    ox + (f64::from(i) * width as f64 / 1200.0 + nudge) * pixel,
                    oy + (f64::from(j) * height as f64 / 1200.0 + nudge * 0.61) * pixel,
                    [0.4, 1.0, 2.0, 2.5, 3.1][z as usize],
                )
            };
            for (a, b, za, zb) in ends {
                let (a, b) = (at(a, za), at(b, zb));
                let (plain, plain_looked) = r.trace(&a, &b, false, &mut Blocker::default());
                let (leaping, looked) = r.trace(&a, &b, true, &mut Blocker::default());
                prop_assert_eq!(leaping, plain, "{:?} → {:?}", a, b);
                prop_assert!(looked <= plain_looked);
            }
            // Along pixel edges and rows exactly: the seam rule.
            for k in 0..height.min(40) {
                let y = oy + k as f64 * pixel;
                let (a, b) = (P3::new(ox - pixel, y, 1.0), P3::new(ox + (width + 1) as f64 * pixel, y, 1.0));
                prop_assert_eq!(r.blocks(&a, &b), plain(&a, &b), "row edge {}", k);
                let y = y + 0.5 * pixel;
                let (a, b) = (P3::new(ox - pixel, y, 1.0), P3::new(ox + (width + 1) as f64 * pixel, y + 0.3 * pixel, 1.0));
                prop_assert_eq!(r.blocks(&a, &b), plain(&a, &b), "row {}", k);
            }
        }

        /// A square overlaps the occupied region as a scan of every pixel's interior says,
        /// whether the middle pixel's clearance answers or the square's pixels are looked at.
        #[test]
        fn square_overlap_agrees_with_every_pixel(
            width in 4usize..80, height in 4usize..80,
            share in prop::sample::select(vec![0.0005, 0.003, 0.02, 0.1]),
            seed in any::<u64>(),
            squares in prop::collection::vec((-40i32..360, -40i32..360, 0u32..40), 1..40),
        ) {
            let pixel = 0.05;
            let r = seeded(width, height, share, seed, pixel);
            let [ox, oy] = r.origin;
            let occupied = r.occupancy();
            for (i, j, half) in squares {
                // Centres and half-sides on the quarter-pixel lattice (edges exactly) and off it.
                let (x, y) = (ox + f64::from(i) / 4.0 * pixel, oy + f64::from(j) / 4.0 * pixel);
                let h = f64::from(half) / 4.0 * pixel + if half % 3 == 0 { 0.0013 } else { 0.0 };
                let (u0, u1) = ((x - h - ox) / pixel, (x + h - ox) / pixel);
                let (v0, v1) = ((y - h - oy) / pixel, (y + h - oy) / pixel);
                let tol = 1e-9;
                let scan = (0..width * height).any(|k| {
                    let (c, row) = ((k % width) as f64, (k / width) as f64);
                    occupied[k] && c < u1 - tol && c + 1.0 > u0 + tol && row < v1 - tol && row + 1.0 > v0 + tol
                });
                prop_assert_eq!(r.overlaps_square(x, y, h), scan, "({}, {}) ± {}", x, y, h);
            }
        }

        /// A grid row's squares marked at once are marked as each square alone says, whatever
        /// the grid's step and offset against the pixels (on their edges, between, finer,
        /// coarser) and however far the squares reach off the map.
        #[test]
        fn a_grid_row_of_squares_is_marked_as_each_square_alone(
            width in 4usize..80, height in 4usize..80,
            share in prop::sample::select(vec![0.0005, 0.003, 0.02, 0.1]),
            seed in any::<u64>(),
            columns in prop::collection::vec(-40i32..360, 1..12),
            (first, step, cells) in (-40i32..360, 1i32..40, 1usize..60),
            half in 0u32..40,
        ) {
            let pixel = 0.05;
            let r = seeded(width, height, share, seed, pixel);
            let [ox, oy] = r.origin;
            let h = f64::from(half) / 4.0 * pixel + if half % 3 == 1 { 0.0013 } else { 0.0 };
            let ys: Vec<f64> = (0..cells)
                .map(|k| oy + f64::from(first + k as i32 * step) / 4.0 * pixel)
                .collect();
            let rows = r.rows_meeting(&ys, h);
            let mut counts = Vec::new();
            for i in columns {
                let x = ox + f64::from(i) / 4.0 * pixel;
                let mut marked = vec![false; cells];
                r.mark_overlapping(x, h, &rows, &mut counts, &mut marked);
                for (k, &y) in ys.iter().enumerate() {
                    prop_assert_eq!(marked[k], r.overlaps_square(x, y, h), "({}, {}) ± {}", x, y, h);
                }
            }
        }

        /// Links from one source to a row of users, as a gain map's rows test them: trying the
        /// last blocking pixel first answers as the plain walk for every user, whatever the
        /// row's spacing against the pixels (on pixel edges, between them, finer, coarser).
        #[test]
        fn the_last_blocker_answers_as_the_plain_walk(
            width in 8usize..200, height in 8usize..200,
            share in prop::sample::select(vec![0.0005, 0.003, 0.02, 0.1]),
            seed in any::<u64>(),
            source in (-4i32..804, -4i32..804, 0u8..5),
            rows in prop::collection::vec((-4i32..804, 0u8..5), 1..6),
            spacing in prop::sample::select(vec![0.25, 0.5, 1.0, 1.5, 4.0]),
        ) {
            let pixel = 0.05;
            let r = seeded(width, height, share, seed, pixel);
            let plain = |a: &P3, b: &P3| plain(&r, a, b);
            let [ox, oy] = r.origin;
            let z = [0.4, 1.0, 2.0, 2.5, 3.1];
            let a = P3::new(
                ox + f64::from(source.0) / 4.0 * pixel,
                oy + f64::from(source.1) / 4.0 * pixel,
                z[source.2 as usize],
            );
            for (x, zu) in rows {
                let mut last = Blocker::default();
                let x = ox + f64::from(x) / 4.0 * pixel;
                for j in 0..((height as f64 + 2.0) / spacing) as usize {
                    let b = P3::new(x, oy + (j as f64 * spacing - 1.0) * pixel, z[zu as usize]);
                    prop_assert_eq!(r.blocks_after(&a, &b, &mut last), plain(&a, &b), "{:?} → {:?}", a, b);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// What a horizon settles, the plain walk answers: a link it calls open is not
        /// blocked, one it calls shut is. Sources on the quarter-pixel lattice (on the edges
        /// and corners of occupied pixels, as a surface mounted on a wall is) and off it;
        /// users everywhere (edges, corners, along an edge, off the map), at heights around
        /// the obstacles' top; rasters from nearly empty to cluttered.
        #[test]
        fn a_horizon_settles_links_as_the_walk_answers(
            width in 8usize..160, height in 8usize..160,
            share in prop::sample::select(vec![0.0005, 0.003, 0.02, 0.1, 0.3]),
            seed in any::<u64>(),
            source in (-4i32..644, -4i32..644, 0u8..3, 0u8..5),
            users in prop::collection::vec((-40i32..680, -40i32..680, 0u8..3, 0u8..5), 1..300),
        ) {
            let pixel = 0.05;
            let r = seeded(width, height, share, seed, pixel);
            let [ox, oy] = r.origin;
            let z = [0.4, 1.0, 2.0, 2.5, 3.1];
            let at = |(i, j, off, zk): (i32, i32, u8, u8)| {
                let nudge = [0.0, 1e-12, 0.137][off as usize];
                P3::new(
                    ox + (f64::from(i) / 4.0 + nudge) * pixel,
                    oy + (f64::from(j) / 4.0 + nudge * 0.61) * pixel,
                    z[zk as usize],
                )
            };
            let a = at(source);
            let Some(horizon) = r.horizon(&a) else {
                prop_assert!(r.interior_at(r.to_pixels(a[0], a[1]).0, r.to_pixels(a[0], a[1]).1));
                return Ok(());
            };
            for &user in &users {
                let b = at(user);
                if let Some(blocked) = r.settled(&horizon, &b) {
                    prop_assert_eq!(blocked, plain(&r, &a, &b), "{:?} → {:?}", a, b);
                }
            }
            // The same users' y on the first user's row, settled at once (the vectorised
            // loop, not only its one-link remainder).
            let first = at(users[0]);
            let ys: Vec<f64> = users.iter().map(|&user| at(user)[1]).collect();
            let mut settled = vec![Settled::Walk; ys.len()];
            r.settle_row(&horizon, RowOfUsers { x: first[0], ys: &ys, z: first[2] }, &mut settled);
            for (&y, &settled) in ys.iter().zip(&settled) {
                let b = P3::new(first[0], y, first[2]);
                prop_assert_eq!(Some(settled), r.settled(&horizon, &b).map(|blocked| {
                    if blocked { Settled::Shut } else { Settled::Open }
                }).or(Some(Settled::Walk)), "{:?} → {:?}", a, b);
                if settled != Settled::Walk {
                    prop_assert_eq!(settled == Settled::Shut, plain(&r, &a, &b), "{:?} → {:?}", a, b);
                }
            }
        }
    }

    /// The horizon settles most links of a cluttered floor (the point of it), both ways: a
    /// tenth of them at least open and a tenth shut, nine tenths in all.
    #[test]
    fn a_horizon_settles_most_links() {
        let r = seeded(200, 150, 0.01, 7, 0.05);
        let [ox, oy] = r.origin;
        let a = P3::new(ox + 3.02, oy + 4.41, 1.5);
        let horizon = r.horizon(&a).expect("a free source");
        let (mut open, mut shut, mut links) = (0, 0, 0);
        for i in 0..100 {
            for j in 0..75 {
                let b = P3::new(
                    ox + 0.1 * i as f64 + 0.013,
                    oy + 0.1 * j as f64 + 0.029,
                    1.0,
                );
                match r.settled(&horizon, &b) {
                    Some(false) => open += 1,
                    Some(true) => shut += 1,
                    None => {}
                }
                links += 1;
            }
        }
        // Measured: 1 139 open and 6 288 shut of 7 500.
        assert!(
            open * 10 > links && shut * 10 > links,
            "{open} open, {shut} shut of {links}"
        );
        assert!(
            (open + shut) * 10 > links * 9,
            "{open} open, {shut} shut of {links}"
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
