//! Mounting an IRS near a point (docs/scenarios.md, "Mounting a surface"): with
//! `mount_within_m`, a surface's centre moves onto the nearest face it can hang on — a wall of
//! the room, a side of an obstacle or of a wall, an edge of the floor plan's occupied pixels —
//! at its own height, and its normal becomes that face's. Scanned walls are ragged and pixel
//! edges sit at `origin + k·resolution`, so a centre typed by hand (or clicked in a viewer)
//! almost never lies exactly on one; this finds it.
//!
//! Which face: the nearest (horizontal distance from the given centre) among those
//! * tall enough to hold the centre's height,
//! * facing the way the given normal does (within 90°), which says which side of a thin wall
//!   the surface hangs on,
//! * with free space in front (a face buried against another obstacle holds nothing).
//!
//! Where on it: the nearest point, moved along the face (when the face is long enough) so that
//! the whole surface's width lies on it rather than hanging past a corner.

use super::{Irs, MOUNT_PROBE_M, Scenario};
use crate::geometry::{Obstructions, Raster};
use crate::input::FieldError;

/// The largest `mount_within_m` (m): a surface is mounted near where it was put, not anywhere.
pub const MAX_MOUNT_WITHIN_M: f64 = 5.0;

/// A face a surface can hang on: the segment `a`→`b` seen from above, the unit horizontal
/// `normal` pointing out of it into free space, and the height it reaches. `pixel_edge` marks one
/// unit edge of the floor plan, which grows into its straight run once chosen ([`run_through`]).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Face {
    a: [f64; 2],
    b: [f64; 2],
    normal: [f64; 2],
    height: f64,
    pixel_edge: bool,
}

impl Face {
    /// The face's parameter t ∈ [0, 1] of the point nearest to p, and that distance.
    fn nearest(&self, p: [f64; 2]) -> (f64, f64) {
        let (dx, dy) = (self.b[0] - self.a[0], self.b[1] - self.a[1]);
        let length2 = dx * dx + dy * dy;
        let t = if length2 > 0.0 {
            (((p[0] - self.a[0]) * dx + (p[1] - self.a[1]) * dy) / length2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = self.at(t);
        (t, (p[0] - q[0]).hypot(p[1] - q[1]))
    }

    fn at(&self, t: f64) -> [f64; 2] {
        [
            self.a[0] + t * (self.b[0] - self.a[0]),
            self.a[1] + t * (self.b[1] - self.a[1]),
        ]
    }

    fn length(&self) -> f64 {
        (self.b[0] - self.a[0]).hypot(self.b[1] - self.a[1])
    }
}

impl Scenario {
    /// Moves every surface that asks for it (`mount_within_m`) onto its face; the field is
    /// then dropped, so the scenario keeps (and hashes) the mounted pose. Errors name the
    /// surface's field.
    pub(super) fn mount_surfaces(&mut self, obstructions: &Obstructions) -> Result<(), FieldError> {
        let faces = self.mounting_faces(obstructions);
        let mut surfaces = std::mem::take(&mut self.surfaces);
        for (k, irs) in surfaces.iter_mut().enumerate() {
            let Some(within) = irs.mount_within_m.take() else {
                continue;
            };
            mount(irs, within, &faces, obstructions, &format!("irss[{k}]"))?;
        }
        self.surfaces = surfaces;
        Ok(())
    }

    /// The room's walls, the obstacles' sides and the walls' sides, each as one face; the
    /// floor plan's edges are found near each surface ([`raster_faces`]).
    fn mounting_faces(&self, obstructions: &Obstructions) -> Vec<Face> {
        let r = &self.room;
        let face = |a, b, normal, height| Face {
            a,
            b,
            normal,
            height,
            pixel_edge: false,
        };
        let mut faces = vec![
            face(
                [r.x_min, r.y_min],
                [r.x_min, r.y_max],
                [1.0, 0.0],
                r.ceiling_m,
            ),
            face(
                [r.x_max, r.y_min],
                [r.x_max, r.y_max],
                [-1.0, 0.0],
                r.ceiling_m,
            ),
            face(
                [r.x_min, r.y_min],
                [r.x_max, r.y_min],
                [0.0, 1.0],
                r.ceiling_m,
            ),
            face(
                [r.x_min, r.y_max],
                [r.x_max, r.y_max],
                [0.0, -1.0],
                r.ceiling_m,
            ),
        ];
        for o in &self.obstacles {
            // The sides as the mount check computes them (centre ± half the size).
            let (hx, hy) = (o.size[0] / 2.0, o.size[1] / 2.0);
            let (x0, x1) = (o.center[0] - hx, o.center[0] + hx);
            let (y0, y1) = (o.center[1] - hy, o.center[1] + hy);
            faces.extend([
                face([x0, y0], [x0, y1], [-1.0, 0.0], o.height_m),
                face([x1, y0], [x1, y1], [1.0, 0.0], o.height_m),
                face([x0, y0], [x1, y0], [0.0, -1.0], o.height_m),
                face([x0, y1], [x1, y1], [0.0, 1.0], o.height_m),
            ]);
        }
        for wall in &obstructions.walls {
            let c = wall.corners();
            let centre = [(c[0][0] + c[2][0]) / 2.0, (c[0][1] + c[2][1]) / 2.0];
            for k in 0..4 {
                let (a, b) = (c[k], c[(k + 1) % 4]);
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                let length = dx.hypot(dy);
                // The perpendicular that points away from the wall's centre.
                let mut normal = [dy / length, -dx / length];
                let mid = [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0];
                if (mid[0] - centre[0]) * normal[0] + (mid[1] - centre[1]) * normal[1] < 0.0 {
                    normal = [-normal[0], -normal[1]];
                }
                faces.push(face(a, b, normal, wall.height()));
            }
        }
        faces
    }
}

/// Moves `irs` onto the nearest suitable face within `within` m (module doc).
fn mount(
    irs: &mut Irs,
    within: f64,
    faces: &[Face],
    obstructions: &Obstructions,
    at: &str,
) -> Result<(), FieldError> {
    let field = format!("{at}.mount_within_m");
    if !(within.is_finite() && within > 0.0 && within <= MAX_MOUNT_WITHIN_M) {
        return Err(FieldError::new(
            field,
            format!("must lie in (0, {MAX_MOUNT_WITHIN_M}] m"),
        ));
    }
    let [x, y, z] = irs.center;
    let n = irs.normal;
    let horizontal = n[0].hypot(n[1]);
    if ![x, y, z, n[0], n[1], n[2]].iter().all(|v| v.is_finite()) || horizontal < 1e-6 {
        // The surface's own checks say what is wrong with its centre or normal.
        return Ok(());
    }
    let raster = obstructions
        .raster
        .as_deref()
        .map(|r| raster_faces(r, [x, y], within))
        .unwrap_or_default();
    let mut near: Vec<(f64, f64, Face)> = faces
        .iter()
        .chain(&raster)
        .filter(|f| f.height >= z && f.normal[0] * n[0] + f.normal[1] * n[1] > 0.0)
        .map(|f| {
            let (t, d) = f.nearest([x, y]);
            (d, t, *f)
        })
        .filter(|&(d, _, _)| d <= within)
        .collect();
    near.sort_by(|p, q| p.0.total_cmp(&q.0));
    let half_width = irs.width_m() / 2.0;
    for (_, t, face) in near {
        // A pixel edge grows into its straight stretch, and t is measured on that.
        let (face, t) = match obstructions.raster.as_deref() {
            Some(r) if face.pixel_edge => {
                let run = run_through(r, face);
                (run, run.nearest([x, y]).0)
            }
            _ => (face, t),
        };
        let length = face.length();
        let t = if length >= 2.0 * half_width {
            t.clamp(half_width / length, 1.0 - half_width / length)
        } else {
            0.5
        };
        let [cx, cy] = face.at(t);
        let front = [
            cx + face.normal[0] * MOUNT_PROBE_M,
            cy + face.normal[1] * MOUNT_PROBE_M,
            z,
        ];
        if obstructions.solid_at(front) {
            continue;
        }
        irs.center = [cx, cy, z];
        irs.normal = [face.normal[0], face.normal[1], 0.0];
        return Ok(());
    }
    Err(FieldError::new(
        field,
        format!(
            "no wall, obstacle side or floor-plan edge facing the way `normal` does (within \
             90°), tall enough and free in front, lies within {within} m of the centre"
        ),
    ))
}

/// The unit edges between an occupied and a free pixel of the floor plan within `within` m of
/// `p`, each a face pointing out of the occupied pixel.
fn raster_faces(r: &Raster, p: [f64; 2], within: f64) -> Vec<Face> {
    let res = r.resolution;
    let pixel = |t: f64, origin: f64| ((t - origin) / res).floor() as i64;
    let reach = (within / res).ceil() as i64 + 1;
    let (pc, pr) = (pixel(p[0], r.origin[0]), pixel(p[1], r.origin[1]));
    let occupied = |c: i64, q: i64| r.is_occupied(c, q);
    let x = |c: i64| r.origin[0] + c as f64 * res;
    let y = |q: i64| r.origin[1] + q as f64 * res;
    let mut faces = Vec::new();
    for q in (pr - reach).max(0)..=(pr + reach).min(r.height as i64 - 1) {
        for c in (pc - reach).max(0)..=(pc + reach).min(r.width as i64) {
            // The edge x = x(c) of row q, between columns c − 1 and c.
            let (left, right) = (occupied(c - 1, q), occupied(c, q));
            if left != right {
                let normal = if left { [1.0, 0.0] } else { [-1.0, 0.0] };
                faces.push(Face {
                    a: [x(c), y(q)],
                    b: [x(c), y(q + 1)],
                    normal,
                    height: r.obstacle_height,
                    pixel_edge: true,
                });
            }
        }
    }
    for c in (pc - reach).max(0)..=(pc + reach).min(r.width as i64 - 1) {
        for q in (pr - reach).max(0)..=(pr + reach).min(r.height as i64) {
            // The edge y = y(q) of column c, between rows q − 1 and q.
            let (below, above) = (occupied(c, q - 1), occupied(c, q));
            if below != above {
                let normal = if below { [0.0, 1.0] } else { [0.0, -1.0] };
                faces.push(Face {
                    a: [x(c), y(q)],
                    b: [x(c + 1), y(q)],
                    normal,
                    height: r.obstacle_height,
                    pixel_edge: true,
                });
            }
        }
    }
    faces
}

/// The straight stretch of pixel edges that `edge` (one unit edge) belongs to: the edges in
/// line with it, facing the same way, without a gap.
fn run_through(r: &Raster, edge: Face) -> Face {
    let res = r.resolution;
    let index = |t: f64, origin: f64| ((t - origin) / res).round() as i64;
    let occupied = |c: i64, q: i64| r.is_occupied(c, q);
    if edge.normal[1] == 0.0 {
        // A vertical edge at column boundary c, rows q0..q1.
        let c = index(edge.a[0], r.origin[0]);
        let solid_left = edge.normal[0] > 0.0;
        let holds = |q: i64| occupied(c - 1, q) == solid_left && occupied(c, q) != solid_left;
        let (mut q0, mut q1) = (index(edge.a[1], r.origin[1]), index(edge.a[1], r.origin[1]));
        while holds(q0 - 1) {
            q0 -= 1;
        }
        while holds(q1 + 1) {
            q1 += 1;
        }
        Face {
            a: [edge.a[0], r.origin[1] + q0 as f64 * res],
            b: [edge.a[0], r.origin[1] + (q1 + 1) as f64 * res],
            ..edge
        }
    } else {
        let q = index(edge.a[1], r.origin[1]);
        let solid_below = edge.normal[1] > 0.0;
        let holds = |c: i64| occupied(c, q - 1) == solid_below && occupied(c, q) != solid_below;
        let (mut c0, mut c1) = (index(edge.a[0], r.origin[0]), index(edge.a[0], r.origin[0]));
        while holds(c0 - 1) {
            c0 -= 1;
        }
        while holds(c1 + 1) {
            c1 += 1;
        }
        Face {
            a: [r.origin[0] + c0 as f64 * res, edge.a[1]],
            b: [r.origin[0] + (c1 + 1) as f64 * res, edge.a[1]],
            ..edge
        }
    }
}
