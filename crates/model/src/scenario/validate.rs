//! A scenario's checks: defaults resolved, then every field, in the document's order, one
//! concern per function, each error naming the field's JSON path.

use super::*;
use crate::floorplan;
use crate::geometry::Obstructions;

impl Scenario {
    pub(super) fn resolve_defaults(&mut self) {
        if let Some(plan) = &mut self.floor_plan
            && plan.obstacle_height_m.is_none()
        {
            plan.obstacle_height_m = Some(self.room.ceiling_m);
        }
        let lambda = self.wavelength_m();
        for irs in &mut self.surfaces {
            if irs.sub_pitch_m.is_none() && lambda.is_finite() {
                irs.sub_pitch_m = Some(lambda / 2.0);
            }
            if irs.grouping == Grouping::Elements && irs.element_pitch_m.is_none() {
                irs.element_pitch_m = irs
                    .sub_pitch_m
                    .map(|p| p / irs.elements_per_sub.max(1) as f64);
            }
        }
    }

    /// Checks every field, in the document's order, each concern in a function of its own;
    /// decodes the floor plan with `image`. The first error found is returned.
    pub(super) fn validate(&mut self, image: ImageFile) -> Result<(), FieldError> {
        self.validate_room_and_grid()?;
        self.validate_obstacles()?;
        self.validate_walls()?;
        self.decode_floor_plan(image)?;
        let obstructions = self.obstructions();
        self.validate_access_points(&obstructions)?;
        self.mount_surfaces(&obstructions)?;
        self.validate_surfaces(&obstructions)?;
        self.validate_robots(&obstructions)?;
        self.validate_channel()
    }

    /// The room's bounds, the name, and a grid whose far walls are cell centres (within the cell
    /// limits).
    fn validate_room_and_grid(&self) -> Result<(), FieldError> {
        let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
        let r = &self.room;
        for (field, v) in [
            ("room.x_min", r.x_min),
            ("room.x_max", r.x_max),
            ("room.y_min", r.y_min),
            ("room.y_max", r.y_max),
            ("room.ceiling_m", r.ceiling_m),
        ] {
            finite(field, v)?;
            if v.abs() > MAX_COORDINATE_M {
                return err(field, &format!("must lie within ±{MAX_COORDINATE_M} m"));
            }
        }
        finite("grid.resolution_m", self.grid.resolution_m)?;
        if let Some(name) = &self.name
            && name.chars().count() > MAX_NAME_CHARS
        {
            return err(
                "name",
                &format!("longer than the limit of {MAX_NAME_CHARS} characters"),
            );
        }
        if r.x_max <= r.x_min {
            return err("room.x_max", "must be greater than room.x_min");
        }
        if r.y_max <= r.y_min {
            return err("room.y_max", "must be greater than room.y_min");
        }
        if r.ceiling_m <= 0.0 {
            return err("room.ceiling_m", "must be positive");
        }
        let d = self.grid.resolution_m;
        if d <= 0.0 {
            return err("grid.resolution_m", "must be positive");
        }
        for (field, span) in [
            ("room.x_max", r.x_max - r.x_min),
            ("room.y_max", r.y_max - r.y_min),
        ] {
            let cells = span / d;
            if cells + 1.0 > MAX_GRID_SIDE as f64 {
                return Err(FieldError::new(
                    "grid.resolution_m",
                    format!(
                        "{field} − min spans {span} m: {} cells at this resolution, above the \
                         limit of {MAX_GRID_SIDE} cells a side",
                        (cells + 1.0).floor()
                    ),
                ));
            }
            if cells < 1.0 - TOL {
                return Err(FieldError::new(
                    "grid.resolution_m",
                    format!("{d} m is larger than the room's span of {span} m"),
                ));
            }
            if (cells - cells.round()).abs() > TOL * cells.max(1.0) {
                return Err(FieldError::new(
                    field,
                    format!(
                        "the room span {span} m is not a whole multiple of grid.resolution_m = {d} m, \
                         so the far wall would not be a cell centre"
                    ),
                ));
            }
        }
        let grid = self.grid();
        if grid.cells() > MAX_GRID_CELLS {
            return Err(FieldError::new(
                "grid.resolution_m",
                format!(
                    "grid of {} × {} = {} cells exceeds the limit of {MAX_GRID_CELLS} cells",
                    grid.nx,
                    grid.ny,
                    grid.cells()
                ),
            ));
        }
        Ok(())
    }

    /// The boxes: finite, positive, inside the room.
    fn validate_obstacles(&self) -> Result<(), FieldError> {
        let r = &self.room;
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(FieldError::new(
                "obstacles",
                format!("more than {MAX_OBSTACLES} obstacles"),
            ));
        }
        for (k, o) in self.obstacles.iter().enumerate() {
            let f = |s: &str| format!("obstacles[{k}].{s}");
            finite_all(&f("center"), &o.center)?;
            finite_all(&f("size"), &o.size)?;
            finite(&f("height_m"), o.height_m)?;
            if o.size.iter().any(|&s| s <= 0.0) {
                return Err(FieldError::new(f("size"), "both sides must be positive"));
            }
            if o.height_m <= 0.0 {
                return Err(FieldError::new(f("height_m"), "must be positive"));
            }
            let (lo, hi) = (
                [o.center[0] - o.size[0] / 2.0, o.center[1] - o.size[1] / 2.0],
                [o.center[0] + o.size[0] / 2.0, o.center[1] + o.size[1] / 2.0],
            );
            if lo[0] < r.x_min - WALL_TOL_M
                || lo[1] < r.y_min - WALL_TOL_M
                || hi[0] > r.x_max + WALL_TOL_M
                || hi[1] > r.y_max + WALL_TOL_M
            {
                return Err(FieldError::new(
                    f("center"),
                    format!(
                        "the footprint [{}, {}] × [{}, {}] reaches outside the room; \
                         clip it to the room (walls need no obstacle: the room ends there)",
                        lo[0], hi[0], lo[1], hi[1]
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Decodes the floor plan's image (read by `image`) into the raster the channel model walks;
    /// the map must cover the room. A scenario derived from a validated one keeps its raster.
    fn decode_floor_plan(&mut self, image: ImageFile) -> Result<(), FieldError> {
        let r = &self.room;
        if let Some(plan) = self.floor_plan.as_ref().filter(|_| self.raster.is_none()) {
            floorplan::check_fields(plan)?;
            let file = image(&plan.image).map_err(|e| FieldError::new("floor_plan.image", e))?;
            let raster = floorplan::decode(plan, &file, r.ceiling_m)?;
            let [[x0, x1], [y0, y1]] = raster.extent();
            if x0 > r.x_min + WALL_TOL_M
                || x1 < r.x_max - WALL_TOL_M
                || y0 > r.y_min + WALL_TOL_M
                || y1 < r.y_max - WALL_TOL_M
            {
                return Err(FieldError::new(
                    "floor_plan",
                    format!(
                        "the map covers [{x0}, {x1}] × [{y0}, {y1}] m, not the whole room [{}, {}] × [{}, {}] m: set origin (and resolution) so that it does",
                        r.x_min, r.x_max, r.y_min, r.y_max
                    ),
                ));
            }
            self.raster = Some(Arc::new(raster));
        }
        Ok(())
    }

    /// The access points (`aps[k]`): at least one, finite, in range, inside the room and outside
    /// every obstacle.
    fn validate_access_points(&self, obstructions: &Obstructions) -> Result<(), FieldError> {
        let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
        if self.access_points.is_empty() {
            return err("aps", "give at least one access point");
        }
        if self.access_points.len() > MAX_APS {
            return Err(FieldError::new(
                "aps",
                format!("more than {MAX_APS} access points"),
            ));
        }
        for (k, ap) in self.access_points.iter().enumerate() {
            let at = format!("aps[{k}]");
            let f = |s: &str| format!("{at}.{s}");
            finite_all(&f("position"), &ap.position)?;
            finite(&f("tx_power_dbm"), ap.tx_power_dbm)?;
            finite(&f("noise_dbm"), ap.noise_dbm)?;
            // Far beyond any radio (1 µW to 1 MW; thermal noise over 1 Hz is −174 dBm), and
            // bounded so that powers and their ratios stay finite in f64.
            if !(-30.0..=90.0).contains(&ap.tx_power_dbm) {
                return err(&f("tx_power_dbm"), "must lie in [-30, 90] dBm");
            }
            if !(-250.0..=30.0).contains(&ap.noise_dbm) {
                return err(&f("noise_dbm"), "must lie in [-250, 30] dBm");
            }
            finite(&f("carrier_ghz"), ap.carrier_ghz)?;
            if !(ap.carrier_ghz > 0.0 && ap.carrier_ghz <= 100.0) {
                return err(
                    &f("carrier_ghz"),
                    "must lie in (0, 100] GHz, the 3GPP InF model's range",
                );
            }
            antenna_gain(&f("antenna_gain_dbi"), ap.antenna_gain_dbi)?;
            if let Some(b) = ap.bandwidth_mhz {
                finite(&f("bandwidth_mhz"), b)?;
                if !(b > 0.0 && b <= MAX_BANDWIDTH_MHZ) {
                    return err(
                        &f("bandwidth_mhz"),
                        &format!("must lie in (0, {MAX_BANDWIDTH_MHZ}] MHz"),
                    );
                }
            }
            self.inside_room(&f("position"), ap.position)?;
            if obstructions.contains(ap.position) {
                return err(&f("position"), "lies inside an obstacle");
            }
        }
        Ok(())
    }

    /// The IRSs (`irss[k]`), one by one and within the limits on N and M together.
    fn validate_surfaces(&self, obstructions: &Obstructions) -> Result<(), FieldError> {
        if self.surfaces.len() > MAX_SURFACES {
            return Err(FieldError::new(
                "irss",
                format!("more than {MAX_SURFACES} surfaces"),
            ));
        }
        let (mut total_n, mut total_m) = (0usize, 0usize);
        for (k, irs) in self.surfaces.iter().enumerate() {
            self.validate_irs(irs, &format!("irss[{k}]"), obstructions)?;
            // Each surface's own products are checked (and so cannot wrap); the sums of at most
            // a few such bounded terms cannot wrap either.
            total_n += irs.subsurfaces();
            total_m += irs.elements();
        }
        if total_n > MAX_SUBSURFACES {
            return Err(FieldError::new(
                "irss",
                format!(
                    "the surfaces have N = {total_n} sub-surfaces in all, above the limit of {MAX_SUBSURFACES}"
                ),
            ));
        }
        if total_m > MAX_ELEMENTS {
            return Err(FieldError::new(
                "irss",
                format!(
                    "the surfaces have M = {total_m} elements in all, above the limit of {MAX_ELEMENTS}"
                ),
            ));
        }
        Ok(())
    }

    /// The mobile robot's antenna and speed, and the static robots: inside the room, outside every
    /// obstacle, with a rate requirement in range.
    fn validate_robots(&self, obstructions: &Obstructions) -> Result<(), FieldError> {
        let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
        let r = &self.room;
        finite("mru.antenna_height_m", self.mru.antenna_height_m)?;
        finite("mru.v_max_mps", self.mru.v_max_mps)?;
        if !(self.mru.antenna_height_m > 0.0 && self.mru.antenna_height_m < r.ceiling_m) {
            return err(
                "mru.antenna_height_m",
                "must lie strictly between the floor and the ceiling",
            );
        }
        if self.mru.v_max_mps <= 0.0 {
            return err("mru.v_max_mps", "must be positive");
        }
        finite("mru.radius_m", self.mru.radius_m)?;
        let room_side = (r.x_max - r.x_min).min(r.y_max - r.y_min);
        if !(self.mru.radius_m >= 0.0 && self.mru.radius_m < room_side / 2.0) {
            return err(
                "mru.radius_m",
                "must be at least 0 and less than half the room's shorter side",
            );
        }

        if self.srus.len() > MAX_SRUS {
            return Err(FieldError::new(
                "srus",
                format!(
                    "{} static robots exceed the limit of {MAX_SRUS}",
                    self.srus.len()
                ),
            ));
        }
        for (k, s) in self.srus.iter().enumerate() {
            let f = |x: &str| format!("srus[{k}].{x}");
            finite_all(&f("position"), &s.position)?;
            finite(&f("min_rate_bps_hz"), s.min_rate_bps_hz)?;
            self.inside_room(&f("position"), s.position)?;
            if obstructions.contains(s.position) {
                return Err(FieldError::new(f("position"), "lies inside an obstacle"));
            }
            if s.min_rate_bps_hz < 0.0 || s.min_rate_bps_hz > 30.0 {
                return Err(FieldError::new(
                    f("min_rate_bps_hz"),
                    "must lie in [0, 30] bit/s/Hz",
                ));
            }
        }
        Ok(())
    }

    /// The channel's Rician factor.
    fn validate_channel(&self) -> Result<(), FieldError> {
        let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
        finite("channel.rician_k_db", self.channel.rician_k_db)?;
        if self.channel.rician_k_db.abs() > 60.0 {
            return err("channel.rician_k_db", "must lie in [-60, 60] dB");
        }
        antenna_gain(
            "channel.rx_antenna_gain_dbi",
            self.channel.rx_antenna_gain_dbi,
        )?;
        finite("channel.fade_margin_db", self.channel.fade_margin_db)?;
        if !(0.0..=MAX_FADE_MARGIN_DB).contains(&self.channel.fade_margin_db) {
            return err(
                "channel.fade_margin_db",
                &format!("must lie in [0, {MAX_FADE_MARGIN_DB}] dB"),
            );
        }
        Ok(())
    }

    /// Checks one surface; `at` is its path (`irss[k]`).
    fn validate_irs(
        &self,
        irs: &Irs,
        at: &str,
        obstructions: &Obstructions,
    ) -> Result<(), FieldError> {
        let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
        finite_all(&format!("{at}.center"), &irs.center)?;
        finite_all(&format!("{at}.normal"), &irs.normal)?;
        self.inside_room(&format!("{at}.center"), irs.center)?;
        let n = irs.normal;
        let norm = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        if (norm - 1.0).abs() > TOL {
            return Err(FieldError::new(
                format!("{at}.normal"),
                format!("must be a unit vector (its length is {norm})"),
            ));
        }
        if n[2].abs() > 1.0 - 1e-6 {
            return err(
                &format!("{at}.normal"),
                "must not be vertical: the IRS hangs on a wall",
            );
        }
        if irs.nx_sub == 0 {
            return err(&format!("{at}.nx_sub"), "must be at least 1");
        }
        if irs.nz_sub == 0 {
            return err(&format!("{at}.nz_sub"), "must be at least 1");
        }
        if irs.elements_per_sub == 0 {
            return err(&format!("{at}.elements_per_sub"), "must be at least 1");
        }
        // Checked products: N and M are derived from user input, and a wrapped product
        // (2^32 × 2^32 = 0 in release builds) would pass a plain comparison.
        let subsurfaces = irs.nx_sub.checked_mul(irs.nz_sub);
        if subsurfaces.is_none_or(|n| n > MAX_SUBSURFACES) {
            return Err(FieldError::new(
                format!("{at}.nx_sub"),
                format!(
                    "N = nx_sub·nz_sub = {}·{} exceeds the limit of {MAX_SUBSURFACES}",
                    irs.nx_sub, irs.nz_sub
                ),
            ));
        }
        let elements = subsurfaces.and_then(|n| n.checked_mul(irs.elements_per_sub));
        if elements.is_none_or(|m| m > MAX_ELEMENTS) {
            return Err(FieldError::new(
                format!("{at}.elements_per_sub"),
                format!(
                    "M = N·N̄ = {}·{} exceeds the limit of {MAX_ELEMENTS}",
                    irs.nx_sub * irs.nz_sub,
                    irs.elements_per_sub
                ),
            ));
        }
        let pitch = irs.sub_pitch_m.unwrap_or(f64::NAN);
        finite(&format!("{at}.sub_pitch_m"), pitch)?;
        if pitch <= 0.0 {
            return err(&format!("{at}.sub_pitch_m"), "must be positive");
        }
        match (irs.grouping, irs.element_pitch_m) {
            (Grouping::Coherent, Some(_)) => {
                return err(
                    &format!("{at}.element_pitch_m"),
                    "applies only to grouping \"elements\"",
                );
            }
            (Grouping::Elements, Some(e)) => {
                finite(&format!("{at}.element_pitch_m"), e)?;
                if e <= 0.0 {
                    return err(&format!("{at}.element_pitch_m"), "must be positive");
                }
                if e * irs.elements_per_sub as f64 > pitch * (1.0 + TOL) {
                    return err(
                        &format!("{at}.element_pitch_m"),
                        "a row of elements_per_sub elements at this pitch is wider than sub_pitch_m: sub-surfaces would overlap",
                    );
                }
            }
            _ => {}
        }
        self.check_irs_extent(irs, at, pitch)?;
        let ahead = |p: [f64; 3]| {
            (p[0] - irs.center[0]) * n[0]
                + (p[1] - irs.center[1]) * n[1]
                + (p[2] - irs.center[2]) * n[2]
        };
        // With several APs a surface may turn its back on some (it serves only those in
        // front of it); one that faces none of them is almost always a typo.
        if self
            .access_points()
            .iter()
            .all(|ap| ahead(ap.position) <= 0.0)
        {
            return err(
                &format!("{at}.normal"),
                "the AP lies behind the IRS surface, so the IRS cannot reflect its signal",
            );
        }
        self.check_irs_mount(irs, at, obstructions)?;
        Ok(())
    }

    fn validate_walls(&self) -> Result<(), FieldError> {
        let r = &self.room;
        if self.walls.len() > MAX_WALLS {
            return Err(FieldError::new(
                "walls",
                format!("more than {MAX_WALLS} walls"),
            ));
        }
        for (k, w) in self.walls.iter().enumerate() {
            let f = |s: &str| format!("walls[{k}].{s}");
            finite_all(&f("from"), &w.from)?;
            finite_all(&f("to"), &w.to)?;
            finite(&f("thickness_m"), w.thickness_m)?;
            finite(&f("height_m"), w.height_m)?;
            if w.thickness_m <= 0.0 {
                return Err(FieldError::new(f("thickness_m"), "must be positive"));
            }
            if w.height_m <= 0.0 {
                return Err(FieldError::new(f("height_m"), "must be positive"));
            }
            if (w.to[0] - w.from[0]).hypot(w.to[1] - w.from[1]) < WALL_TOL_M {
                return Err(FieldError::new(
                    f("to"),
                    "must differ from `from`: a wall needs a length",
                ));
            }
            for (end, p) in [("from", w.from), ("to", w.to)] {
                if p[0] < r.x_min - WALL_TOL_M
                    || p[0] > r.x_max + WALL_TOL_M
                    || p[1] < r.y_min - WALL_TOL_M
                    || p[1] > r.y_max + WALL_TOL_M
                {
                    return Err(FieldError::new(f(end), "lies outside the room"));
                }
            }
        }
        Ok(())
    }

    /// The whole surface fits in the room: its nx_sub × nz_sub tiles of `pitch` (each sub-surface
    /// a square of side `sub_pitch_m`), laid along the wall's horizontal axis ẑ × n and the
    /// vertical, stay between the room's walls, the floor and the ceiling. Besides catching a
    /// pitch typed in the wrong unit, this bounds every element position, so no distance in the
    /// channel model overflows (a 10³⁰⁸ m pitch once made every cascaded gain NaN).
    fn check_irs_extent(&self, irs: &Irs, at: &str, pitch: f64) -> Result<(), FieldError> {
        let (c, n, r) = (irs.center, irs.normal, &self.room);
        let horizontal = n[0].hypot(n[1]);
        // ẑ × n = (−n_y, n_x, 0), normalised: the wall's horizontal axis.
        let axis = [-n[1] / horizontal, n[0] / horizontal];
        let half_width = irs.width_m() / 2.0;
        let half_height = irs.height_m() / 2.0;
        let ends = [-1.0, 1.0].map(|s| {
            [
                c[0] + s * half_width * axis[0],
                c[1] + s * half_width * axis[1],
            ]
        });
        let along_fits = ends.iter().all(|p| {
            p[0] >= r.x_min - WALL_TOL_M
                && p[0] <= r.x_max + WALL_TOL_M
                && p[1] >= r.y_min - WALL_TOL_M
                && p[1] <= r.y_max + WALL_TOL_M
        });
        let up_fits =
            c[2] - half_height >= -WALL_TOL_M && c[2] + half_height <= r.ceiling_m + WALL_TOL_M;
        if along_fits && up_fits {
            return Ok(());
        }
        // Metres as people write them, or in scientific notation when absurdly large.
        let metres = |v: f64| {
            if v < 1e6 {
                format!("{v:.3} m")
            } else {
                format!("{v:.3e} m")
            }
        };
        Err(FieldError::new(
            format!("{at}.sub_pitch_m"),
            format!(
                "the surface ({} × {} sub-surfaces of {}: {} wide and {} tall around its \
                 centre) does not fit in the room: it would reach past a wall, the floor or the \
                 ceiling",
                irs.nx_sub,
                irs.nz_sub,
                metres(pitch),
                metres(2.0 * half_width),
                metres(2.0 * half_height)
            ),
        ))
    }

    /// An IRS hangs on something: a wall of the room or a face of an obstacle, with its normal
    /// pointing away from that surface (into free space). One that floats in the room or faces
    /// into its own wall is almost always a typo in `center` or `normal`.
    fn check_irs_mount(
        &self,
        irs: &Irs,
        at: &str,
        obstructions: &Obstructions,
    ) -> Result<(), FieldError> {
        let (c, n, r) = (irs.center, irs.normal, &self.room);
        let near = |a: f64, b: f64| (a - b).abs() <= WALL_TOL_M;
        // Each surface the centre lies on, as its direction into free space (along x or y).
        let mut on: Vec<[f64; 2]> = [
            (near(c[0], r.x_min), [1.0, 0.0]),
            (near(c[0], r.x_max), [-1.0, 0.0]),
            (near(c[1], r.y_min), [0.0, 1.0]),
            (near(c[1], r.y_max), [0.0, -1.0]),
        ]
        .into_iter()
        .filter_map(|(is_on, away)| is_on.then_some(away))
        .collect();
        for o in self
            .obstacles
            .iter()
            .filter(|o| c[2] <= o.height_m + WALL_TOL_M)
        {
            let (hx, hy) = (o.size[0] / 2.0, o.size[1] / 2.0);
            let within_x = (c[0] - o.center[0]).abs() <= hx + WALL_TOL_M;
            let within_y = (c[1] - o.center[1]).abs() <= hy + WALL_TOL_M;
            let faces = [
                (within_y && near(c[0], o.center[0] - hx), [-1.0, 0.0]),
                (within_y && near(c[0], o.center[0] + hx), [1.0, 0.0]),
                (within_x && near(c[1], o.center[1] - hy), [0.0, -1.0]),
                (within_x && near(c[1], o.center[1] + hy), [0.0, 1.0]),
            ];
            on.extend(
                faces
                    .into_iter()
                    .filter_map(|(is_on, away)| is_on.then_some(away)),
            );
        }
        if on.is_empty() && !(self.walls.is_empty() && self.raster.is_none()) {
            // Walls at any angle and floor-plan pixels: probe just behind and just in front of
            // the surface along the normal's horizontal part.
            let h = (n[0].hypot(n[1]), [n[0], n[1]]);
            let (dx, dy) = (h.1[0] / h.0 * MOUNT_PROBE_M, h.1[1] / h.0 * MOUNT_PROBE_M);
            let behind = obstructions.solid_at([c[0] - dx, c[1] - dy, c[2]]);
            let front = obstructions.solid_at([c[0] + dx, c[1] + dy, c[2]]);
            match (behind, front) {
                (true, false) => return Ok(()),
                (true, true) => {
                    return Err(FieldError::new(
                        format!("{at}.center"),
                        "lies inside a wall or the floor plan's occupied pixels: put it on the \
                         surface (for a floor plan, on a pixel edge at origin + k·resolution), \
                         or add mount_within_m to mount it on the nearest face",
                    ));
                }
                (false, true) => {
                    return Err(FieldError::new(
                        format!("{at}.normal"),
                        "the IRS faces into the wall it hangs on; the normal must point into \
                         the room",
                    ));
                }
                (false, false) => {}
            }
        }
        if on.is_empty() {
            return Err(FieldError::new(
                format!("{at}.center"),
                "the IRS is on no wall and no obstacle face: put its centre on a wall of the room \
                 (e.g. y = room.y_min), on an obstacle's or a wall's side, or on the edge of \
                 the floor plan's occupied pixels; or add mount_within_m (e.g. 0.5) to mount it \
                 on the nearest one",
            ));
        }
        if !on.iter().any(|d| d[0] * n[0] + d[1] * n[1] > 0.0) {
            return Err(FieldError::new(
                format!("{at}.normal"),
                "the IRS faces into the surface it hangs on; the normal must point into the room",
            ));
        }
        Ok(())
    }

    fn inside_room(&self, field: &str, p: [f64; 3]) -> Result<(), FieldError> {
        let r = &self.room;
        let inside = p[0] >= r.x_min && p[0] <= r.x_max && p[1] >= r.y_min && p[1] <= r.y_max;
        if !inside {
            return Err(FieldError::new(field, "lies outside the room's floor plan"));
        }
        if p[2] < 0.0 || p[2] > r.ceiling_m {
            return Err(FieldError::new(
                field,
                "height must lie between the floor and room.ceiling_m",
            ));
        }
        Ok(())
    }
}

fn finite(field: &str, v: f64) -> Result<(), FieldError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(FieldError::new(field, "must be a finite number"))
    }
}

fn antenna_gain(field: &str, v: f64) -> Result<(), FieldError> {
    finite(field, v)?;
    if v.abs() > MAX_ANTENNA_GAIN_DBI {
        return Err(FieldError::new(
            field,
            format!("must lie in [-{MAX_ANTENNA_GAIN_DBI}, {MAX_ANTENNA_GAIN_DBI}] dBi"),
        ));
    }
    Ok(())
}

fn finite_all(field: &str, v: &[f64]) -> Result<(), FieldError> {
    v.iter().try_for_each(|&x| finite(field, x))
}
