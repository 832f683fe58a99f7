//! Blockage seen from one fixed point: the links a map evaluates all start at an AP or an IRS
//! centre, so for each such source the boxes and walls are sorted once by the directions they
//! cover, and a link to a user is tested only against the few obstacles in its direction.
//!
//! The answer is exactly [`Obstructions::blocks`] from the source (tested against it): the index
//! only skips an obstacle whose footprint the link's 2D projection cannot meet. Directions are
//! split into [`SECTORS`] equal sectors of a pseudo-angle; an obstacle is listed in every sector
//! its footprint's angular extent touches, widened by one sector on each side so that rounding
//! in the angle of a corner never drops it. An obstacle within reach of the source (its
//! footprint closer than [`NEAR_M`]) is listed in every sector, as is every obstacle when a link
//! has no horizontal extent (a user straight below the source). The raster of a floor plan is
//! walked as before: its cost is already the pixels crossed.

use super::{Aabb, Horizon, Obstructions, P3, Wall};
use std::sync::OnceLock;

/// Sectors of the full turn. At 1024 a sector is 0.35°: a 2 m machine 20 m from the AP spans
/// 5.7°, 17 sectors, so a link meets the one or two obstacles in its direction instead of all
/// of them. The index takes 4 kB per source and kind of obstacle (boxes, walls) plus 4 bytes per
/// (obstacle, sector).
const SECTORS: usize = 1024;

/// An obstacle whose footprint comes closer to the source than this (m) covers directions the
/// corner angles do not bound (the source may be on or in its footprint): it is kept in every
/// sector. Far below any mounting offset, above rounding.
const NEAR_M: f64 = 1e-6;

/// The boxes and walls of a floor indexed by direction from one source point. It holds indices
/// only: queries take the [`Obstructions`] it was built from.
#[derive(Debug, Clone)]
pub struct SightLines {
    source: P3,
    /// `box_in_sector[box_start[s]..box_start[s + 1]]` index the boxes sector `s` meets (4
    /// bytes each rather than a copy: an obstacle near the source is listed in up to every
    /// sector).
    box_start: Vec<u32>,
    box_in_sector: Vec<u32>,
    wall_start: Vec<u32>,
    wall_in_sector: Vec<u32>,
    /// The floor plan's horizon from the source ([`SightLines::horizon`]), worked out on first
    /// use: a map's rows use it, a link tested on its own does not.
    horizon: OnceLock<Option<Horizon>>,
}

impl SightLines {
    /// The index of `obstructions` as seen from `source`.
    pub fn new(obstructions: &Obstructions, source: [f64; 3]) -> SightLines {
        let source = P3::from(source);
        let (box_start, box_in_sector) = bucket(&obstructions.boxes, |b| {
            sectors_of(&source, &box_corners(b), box_is_near(b, &source))
        });
        let (wall_start, wall_in_sector) = bucket(&obstructions.walls, |w| {
            sectors_of(&source, &wall_corners(w), wall_is_near(w, &source))
        });
        SightLines {
            source,
            box_start,
            box_in_sector,
            wall_start,
            wall_in_sector,
            horizon: OnceLock::new(),
        }
    }

    /// The floor plan's [`Horizon`] from the source (`None` without a plan, or from a source on
    /// an occupied pixel); `obstructions` are the ones this index was built from.
    pub fn horizon(&self, obstructions: &Obstructions) -> Option<&Horizon> {
        self.horizon
            .get_or_init(|| {
                let raster = obstructions.raster.as_ref()?;
                raster.horizon(&self.source)
            })
            .as_ref()
    }

    /// The point every link of this index starts at.
    pub fn source(&self) -> &P3 {
        &self.source
    }

    /// [`Obstructions::blocks_segment`] from the source to `q`; `obstructions` are the ones
    /// this index was built from.
    pub fn blocks(&self, obstructions: &Obstructions, q: &P3) -> bool {
        let source = &self.source;
        let (dx, dy) = (q[0] - source[0], q[1] - source[1]);
        let listed = if dx.abs() + dy.abs() > 0.0 {
            let s = sector(pseudo_angle(dx, dy));
            let boxes = in_sector(&self.box_start, &self.box_in_sector, s);
            let walls = in_sector(&self.wall_start, &self.wall_in_sector, s);
            boxes
                .iter()
                .any(|&k| obstructions.boxes[k as usize].blocks(source, q))
                || walls
                    .iter()
                    .any(|&k| obstructions.walls[k as usize].blocks(source, q))
        } else {
            obstructions.boxes.iter().any(|b| b.blocks(source, q))
                || obstructions.walls.iter().any(|w| w.blocks(source, q))
        };
        listed
            || obstructions
                .raster
                .as_ref()
                .is_some_and(|r| r.blocks(source, q))
    }

    /// The boxes and walls a link from the source to `q` is tested against (what such a test
    /// costs; see `radiomap::cost`).
    pub fn listed_towards(&self, obstructions: &Obstructions, q: &P3) -> (usize, usize) {
        let (dx, dy) = (q[0] - self.source[0], q[1] - self.source[1]);
        if dx.abs() + dy.abs() > 0.0 {
            let s = sector(pseudo_angle(dx, dy));
            (
                in_sector(&self.box_start, &self.box_in_sector, s).len(),
                in_sector(&self.wall_start, &self.wall_in_sector, s).len(),
            )
        } else {
            (obstructions.boxes.len(), obstructions.walls.len())
        }
    }

    /// Bytes an index of `boxes` boxes and `walls` walls is expected to hold, before it is built:
    /// the sector starts of each kind present and each obstacle listed in 100 sectors (35°): on
    /// the paper's 20 m floor its five 4 m boxes are listed in about 73 sectors per source on
    /// average (from the map's weighed bytes), a 2 m machine 20 m away in 17.
    /// With a floor plan, a map's rows also work out the plan's horizon from the source.
    pub fn estimated_heap_bytes(boxes: usize, walls: usize, floor_plan: bool) -> usize {
        let starts = 4 * (SECTORS + 1) * (usize::from(boxes > 0) + usize::from(walls > 0));
        starts + 4 * 100 * (boxes + walls) + if floor_plan { Horizon::HEAP_BYTES } else { 0 }
    }

    /// Bytes of the index, and of the horizon once worked out.
    pub fn heap_bytes(&self) -> usize {
        4 * (self.box_start.capacity()
            + self.wall_start.capacity()
            + self.box_in_sector.capacity()
            + self.wall_in_sector.capacity())
            + self
                .horizon
                .get()
                .and_then(Option::as_ref)
                .map_or(0, Horizon::heap_bytes)
    }
}

/// The indices listed for sector `s` (none when the kind has no obstacles: its lists are empty).
fn in_sector<'a>(start: &[u32], listed: &'a [u32], s: usize) -> &'a [u32] {
    match start.get(s..=s + 1) {
        Some(&[from, to]) => &listed[from as usize..to as usize],
        _ => &[],
    }
}

/// A monotone stand-in for atan2(dy, dx) mapped to [0, 4): 0 along +x, 1 along +y, 2 along −x,
/// 3 along −y, and exactly 2 more (mod 4) for the opposite direction. One division instead of
/// an arctangent; sectors need only the order of directions, not the angle.
pub(super) fn pseudo_angle(dx: f64, dy: f64) -> f64 {
    let p = dy / (dx.abs() + dy.abs());
    if dx >= 0.0 {
        if dy >= 0.0 { p } else { 4.0 + p }
    } else {
        2.0 - p
    }
}

fn sector(angle: f64) -> usize {
    ((angle * (SECTORS as f64 / 4.0)) as usize).min(SECTORS - 1)
}

/// The sectors a convex footprint with these corners covers from `source`, as a run
/// `first..=last` that may wrap past the last sector: the cone of the corner directions (a
/// convex polygon not containing the source subtends less than a half turn, bounded by its
/// vertices), one sector wider each side; every sector when `near`.
fn sectors_of(source: &P3, corners: &[[f64; 2]; 4], near: bool) -> (i64, i64) {
    let every = (0, SECTORS as i64 - 1);
    if near {
        return every;
    }
    let angle = |c: &[f64; 2]| pseudo_angle(c[0] - source[0], c[1] - source[1]);
    let centre = [
        corners.iter().map(|c| c[0]).sum::<f64>() / 4.0,
        corners.iter().map(|c| c[1]).sum::<f64>() / 4.0,
    ];
    let middle = angle(&centre);
    // Each corner's angle relative to the centre's, in (−2, 2]: less than a half turn apart.
    let offsets = corners.iter().map(|c| {
        let d = angle(c) - middle;
        if d > 2.0 {
            d - 4.0
        } else if d <= -2.0 {
            d + 4.0
        } else {
            d
        }
    });
    let (lo, hi) = offsets.fold((0.0f64, 0.0f64), |(lo, hi), d| (lo.min(d), hi.max(d)));
    let per_unit = SECTORS as f64 / 4.0;
    let first = ((middle + lo) * per_unit).floor() as i64 - 1;
    let last = ((middle + hi) * per_unit).floor() as i64 + 1;
    if last - first + 1 >= SECTORS as i64 {
        every
    } else {
        (first, last)
    }
}

/// Compressed per-sector lists of the items' indices (counted, then filled: no list per
/// sector), each listed in the run of sectors `sectors` gives.
fn bucket<T>(items: &[T], sectors: impl Fn(&T) -> (i64, i64)) -> (Vec<u32>, Vec<u32>) {
    if items.is_empty() {
        return (Vec::new(), Vec::new());
    }
    let runs: Vec<(i64, i64)> = items.iter().map(sectors).collect();
    let wrapped = |s: i64| s.rem_euclid(SECTORS as i64) as usize;
    let mut start = vec![0u32; SECTORS + 1];
    for &(first, last) in &runs {
        (first..=last).for_each(|s| start[wrapped(s) + 1] += 1);
    }
    for s in 0..SECTORS {
        start[s + 1] += start[s];
    }
    let mut next = start.clone();
    let mut listed = vec![0u32; start[SECTORS] as usize];
    for (k, &(first, last)) in runs.iter().enumerate() {
        for s in first..=last {
            let slot = &mut next[wrapped(s)];
            listed[*slot as usize] = k as u32;
            *slot += 1;
        }
    }
    (start, listed)
}

fn box_corners(b: &Aabb) -> [[f64; 2]; 4] {
    let ([x0, y0, _], [x1, y1, _]) = (b.lo, b.hi);
    [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
}

fn box_is_near(b: &Aabb, source: &P3) -> bool {
    (0..2).all(|k| source[k] > b.lo[k] - NEAR_M && source[k] < b.hi[k] + NEAR_M)
}

fn wall_corners(w: &Wall) -> [[f64; 2]; 4] {
    w.corners()
}

fn wall_is_near(w: &Wall, source: &P3) -> bool {
    let local = w.local_coordinates(source);
    (0..2).all(|k| local[k] > w.local.lo[k] - NEAR_M && local[k] < w.local.hi[k] + NEAR_M)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::tests::{point, scene};
    use proptest::prelude::*;

    #[test]
    fn pseudo_angles_follow_the_true_angle() {
        let mut previous = -1.0;
        for k in 0..3600 {
            let t = k as f64 * std::f64::consts::TAU / 3600.0;
            let a = pseudo_angle(t.cos(), t.sin());
            assert!(a > previous && (0.0..4.0).contains(&a), "{t}: {a}");
            let opposite = pseudo_angle(-t.cos(), -t.sin());
            assert!(((opposite - a).rem_euclid(4.0) - 2.0).abs() < 1e-12, "{t}");
            previous = a;
        }
    }

    proptest! {
        /// The index answers exactly what testing every obstacle answers, for random links and
        /// for the links that aim at a corner or run along a face (the grazing cases).
        #[test]
        fn the_index_equals_testing_every_obstacle(
            scene in scene(),
            source in point(),
            targets in proptest::collection::vec(point(), 40),
        ) {
            let sight = SightLines::new(&scene, source);
            let mut aimed: Vec<[f64; 3]> = targets.clone();
            for b in &scene.boxes {
                for c in box_corners(b) {
                    // Beyond the corner on the ray from the source, and just beside it.
                    let ray = [c[0] - source[0], c[1] - source[1]];
                    for (scale, nudge) in [(1.0, 0.0), (1.5, 0.0), (2.0, 1e-9), (2.0, -1e-9)] {
                        aimed.push([
                            source[0] + ray[0] * scale - ray[1] * nudge,
                            source[1] + ray[1] * scale + ray[0] * nudge,
                            0.5,
                        ]);
                    }
                }
                aimed.push([b.lo[0], source[1], 1.0]);
                aimed.push([source[0], b.hi[1], 1.0]);
            }
            aimed.push([source[0], source[1], 0.0]);
            for q in aimed {
                let q = P3::from(q);
                prop_assert_eq!(
                    sight.blocks(&scene, &q),
                    scene.blocks_segment(&P3::from(source), &q),
                    "source {:?} to {:?}", source, q
                );
            }
        }
    }

    /// A source on an obstacle's face (an IRS on a pillar) has it around half its directions:
    /// the links into the pillar are blocked, the others not, as testing every obstacle says.
    #[test]
    fn an_obstacle_at_the_source_is_in_every_sector() {
        let scene = Obstructions {
            boxes: vec![Aabb {
                lo: [-1.0, -1.0, 0.0],
                hi: [1.0, 1.0, 3.0],
            }],
            walls: Vec::new(),
            raster: None,
        };
        let source = [1.0, 0.0, 2.0];
        let sight = SightLines::new(&scene, source);
        let mut blocked = 0;
        for k in 0..64 {
            let t = (k as f64 + 0.5) * std::f64::consts::TAU / 64.0;
            let q = P3::new(1.0 + 5.0 * t.cos(), 5.0 * t.sin(), 1.5);
            let expected = scene.blocks_segment(&P3::from(source), &q);
            assert_eq!(sight.blocks(&scene, &q), expected, "direction {t}");
            blocked += usize::from(expected);
        }
        assert_eq!(blocked, 32);
    }
}
