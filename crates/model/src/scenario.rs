//! The scenario: one JSON document describing a floor, its obstacles, the AP, the optional IRS,
//! the mobile robot (MRU) and the static robots (SRUs) — docs/model.md §1.
//!
//! Parsing is strict (unknown fields are an error) and every check names the offending field by
//! its JSON path, so a fleet manager can fix a document without reading code. Defaults the spec
//! fixes (`sub_pitch_m = λ/2`, `grouping = coherent`, `rician_k_db = 3`) are resolved at parse
//! time, so the canonical form — and therefore the content hash — is the same whether a default
//! was written out or omitted.

use crate::floorplan::{self, FloorPlan};
use crate::geometry::{Aabb, Obstructions, Raster, Wall};
use crate::input::{FieldError, present};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Reads a floor plan's image file from the text a document carries in `floor_plan.image`
/// (base64, decoded by the answers crate), or says why it cannot.
pub type ImageFile<'a> = &'a dyn Fn(&str) -> Result<Vec<u8>, String>;

/// The [`ImageFile`] of a scenario derived from a validated one, which keeps its decoded floor
/// plan (and of documents without one): never asked for a file.
fn kept_raster(_: &str) -> Result<Vec<u8>, String> {
    Err("a derived scenario keeps its decoded floor plan".into())
}

/// Speed of light (m/s), for λ = c / f_c.
pub const SPEED_OF_LIGHT: f64 = 299_792_458.0;
/// Largest grid a scenario may define: a 1001 × 1001 map (≈ 8 MB of values).
pub const MAX_GRID_CELLS: usize = 1001 * 1001;
/// Largest number of IRS sub-surfaces N (phase vector length), all surfaces together.
pub const MAX_SUBSURFACES: usize = 1024;
/// Largest number of IRS elements M = N · N̄, all surfaces together.
pub const MAX_ELEMENTS: usize = 200_000;
/// Largest number of access points on one floor: a gain map evaluates every cell once per AP.
pub const MAX_APS: usize = 8;
/// Largest number of IRSs on one floor: each adds a blockage test and a path-loss evaluation
/// per cell; 16 covers a hall with a surface on every pillar face we have seen planned.
pub const MAX_SURFACES: usize = 16;
/// Largest number of static robots K; NOMA searches all (K+1)! decoding orders.
pub const MAX_SRUS: usize = 4;
/// Largest number of obstacles (boxes); each is tested against every link.
pub const MAX_OBSTACLES: usize = 1000;
/// Largest number of walls; each is tested against every link, like a box.
pub const MAX_WALLS: usize = 1000;
/// Longest scenario name, in characters: a label for listings, not a document store.
pub const MAX_NAME_CHARS: usize = 200;
/// Most cells along one axis of the grid: a 1 km corridor at 0.1 m. Together with
/// [`MAX_GRID_CELLS`] it keeps absurd aspect ratios (a 10⁶ × 1 grid) out, which would otherwise
/// give pictures and masks a side no image format holds.
pub const MAX_GRID_SIDE: usize = 10_001;
/// Largest |coordinate| (m) of the room, and so of everything inside it: a floor is far smaller,
/// and beyond ~10⁵ m squared distances lose the millimetre precision blockage tests rely on.
pub const MAX_COORDINATE_M: f64 = 100_000.0;
/// Relative tolerance for "the room is a whole number of cells wide" and "the normal is unit":
/// loose enough for spans and normals typed with six significant digits.
const TOL: f64 = 1e-6;

/// How far (m) a point may sit from a wall or an obstacle face and still count as on it: well
/// below any grid resolution, above the rounding of coordinates typed to the millimetre.
const WALL_TOL_M: f64 = 1e-3;

/// How far (m) behind and in front of an IRS on a wall or a floor-plan edge the mount check
/// looks for something solid and for free space: twice [`WALL_TOL_M`], so a centre within that
/// tolerance of the surface still finds it, far thinner than any wall or pixel.
const MOUNT_PROBE_M: f64 = 2.0 * WALL_TOL_M;

/// A scenario that has passed [`Scenario::validated`]: every field finite and consistent. Its
/// JSON document (parsing, canonical form, id) is the answers crate's (`irs_answers::scenario`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Free-text label; part of the document (and so of its hash).
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    pub name: Option<String>,
    pub room: Room,
    pub grid: GridSpec,
    #[serde(default)]
    pub obstacles: Vec<Obstacle>,
    /// Straight walls at any angle (what a CAD plan gives). Left out of the canonical form when
    /// empty, so scenarios written before walls existed keep their ids.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub walls: Vec<WallSpec>,
    /// A ROS occupancy-grid map of the floor (see [`crate::floorplan`]).
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    pub floor_plan: Option<FloorPlan>,
    /// The decoded floor plan, made once at validation and shared by every map built from it.
    #[serde(skip)]
    raster: Option<Arc<Raster>>,
    /// The access point (the paper's set-up) …
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    ap: Option<AccessPoint>,
    /// … or several, each on its own channel (docs/model.md §3). As with the IRSs, one AP is
    /// kept and written as `ap`, so a one-AP scenario has the same id whichever way it was
    /// written. Read them with [`Scenario::access_points`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    aps: Vec<AccessPoint>,
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    irs: Option<Irs>,
    /// Several IRSs, each with its own pose, sub-surfaces and grouping (docs/model.md §2). One
    /// surface is kept (and written in the canonical form) as `irs`, two or more as `irss`, so
    /// a one-IRS scenario has the same id whichever way it was written. Read them with
    /// [`Scenario::surfaces`].
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    irss: Vec<Irs>,
    pub mru: Mru,
    #[serde(default)]
    pub srus: Vec<Sru>,
    #[serde(default)]
    pub channel: ChannelSpec,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Room {
    pub x_min: f64,
    pub x_max: f64,
    pub y_min: f64,
    pub y_max: f64,
    pub ceiling_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Δ = Δx = Δy (m).
    pub resolution_m: f64,
}

/// An axis-aligned box standing on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    pub center: [f64; 2],
    pub size: [f64; 2],
    pub height_m: f64,
}

/// A straight wall from `from` to `to` (its centre line), standing on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    pub from: [f64; 2],
    pub to: [f64; 2],
    pub thickness_m: f64,
    pub height_m: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccessPoint {
    pub position: [f64; 3],
    /// P_max (dBm).
    pub tx_power_dbm: f64,
    /// σ², the receiver noise power of every robot (dBm).
    pub noise_dbm: f64,
    /// f_c (GHz).
    pub carrier_ghz: f64,
}

/// How the N̄ elements of a sub-surface combine (docs/model.md §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Grouping {
    /// w̃_n = N̄ × the cascaded LoS coefficient at the sub-surface centre.
    #[default]
    Coherent,
    /// Each element at its own position; w̃_n sums the N̄ element coefficients.
    Elements,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Irs {
    pub center: [f64; 3],
    /// Unit vector pointing into the room.
    pub normal: [f64; 3],
    /// Sub-surfaces along the wall's horizontal axis.
    pub nx_sub: usize,
    /// Sub-surfaces along the wall's vertical axis.
    pub nz_sub: usize,
    /// N̄, elements per sub-surface (M = N·N̄).
    pub elements_per_sub: usize,
    /// Centre-to-centre spacing of sub-surfaces (m); default λ/2.
    #[serde(default, deserialize_with = "present")]
    pub sub_pitch_m: Option<f64>,
    #[serde(default)]
    pub grouping: Grouping,
    /// Spacing of the elements of one sub-surface, laid out in a row along the wall's horizontal
    /// axis (`elements` grouping only); default `sub_pitch_m / N̄`, so the row tiles the
    /// sub-surface.
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    pub element_pitch_m: Option<f64>,
}

impl Irs {
    /// N, the number of independently phased sub-surfaces.
    pub fn subsurfaces(&self) -> usize {
        self.nx_sub * self.nz_sub
    }
    /// M = N · N̄, the number of reflecting elements.
    pub fn elements(&self) -> usize {
        self.subsurfaces() * self.elements_per_sub
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mru {
    /// H_0 (m).
    pub antenna_height_m: f64,
    /// V_max (m/s).
    pub v_max_mps: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sru {
    pub position: [f64; 3],
    /// r̄_s (bit/s/Hz).
    pub min_rate_bps_hz: f64,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum PathLossModel {
    /// 3GPP TR 38.901 indoor factory, sparse clutter, high BS (paper Section IV).
    #[default]
    #[serde(rename = "3gpp_inf_sh")]
    ThreeGppInfSh,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// κ (dB), the Rician factor of every LoS link.
    #[serde(default = "default_rician_k_db")]
    pub rician_k_db: f64,
    #[serde(default)]
    pub path_loss: PathLossModel,
}

fn default_rician_k_db() -> f64 {
    3.0
}

impl Default for ChannelSpec {
    fn default() -> Self {
        ChannelSpec {
            rician_k_db: default_rician_k_db(),
            path_loss: PathLossModel::default(),
        }
    }
}

/// The cell lattice (docs/model.md §1): centres at `x_min + i·Δ`, both walls included.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Grid {
    pub nx: usize,
    pub ny: usize,
    pub x_min: f64,
    pub y_min: f64,
    pub resolution_m: f64,
}

impl Grid {
    pub fn cells(&self) -> usize {
        self.nx * self.ny
    }
    /// Flat index of cell (i, j); i runs along x, j along y (the paper's C_{i,j}).
    #[inline]
    pub fn index(&self, i: usize, j: usize) -> usize {
        i * self.ny + j
    }
    #[inline]
    pub fn cell_of(&self, index: usize) -> (usize, usize) {
        (index / self.ny, index % self.ny)
    }
    /// q^Δ_{i,j}, the horizontal centre of cell (i, j) (paper eq. 8).
    #[inline]
    pub fn centre(&self, i: usize, j: usize) -> [f64; 2] {
        [
            self.x_min + i as f64 * self.resolution_m,
            self.y_min + j as f64 * self.resolution_m,
        ]
    }
    fn x_max(&self) -> f64 {
        self.x_min + (self.nx - 1) as f64 * self.resolution_m
    }
    fn y_max(&self) -> f64 {
        self.y_min + (self.ny - 1) as f64 * self.resolution_m
    }
    /// The cell whose centre is nearest to (x, y), or `None` outside the room.
    pub fn snap(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let slack = 1e-9 * self.resolution_m.max(1.0);
        if !x.is_finite() || !y.is_finite() {
            return None;
        }
        if x < self.x_min - slack || x > self.x_max() + slack {
            return None;
        }
        if y < self.y_min - slack || y > self.y_max() + slack {
            return None;
        }
        let i = ((x - self.x_min) / self.resolution_m).round() as usize;
        let j = ((y - self.y_min) / self.resolution_m).round() as usize;
        Some((i.min(self.nx - 1), j.min(self.ny - 1)))
    }
}

impl Scenario {
    /// Validates a scenario as its document was read: resolves defaults, checks every field,
    /// decodes the floor plan (its image file's bytes from `image`, which reads the text of
    /// `floor_plan.image`: the answers crate decodes the document's base64) and keeps a
    /// one-element `irss` or `aps` as `irs` or `ap` (the canonical form). Every way to make a
    /// scenario ends here; a scenario derived from a validated one keeps its decoded raster, so
    /// `image` is not called again.
    pub fn validated(mut self, image: ImageFile) -> Result<Scenario, FieldError> {
        self.resolve_defaults();
        self.validate(image)?;
        if self.irss.len() == 1 {
            self.irs = self.irss.pop();
        }
        if self.aps.len() == 1 {
            self.ap = self.aps.pop();
        }
        Ok(self)
    }

    /// The IRSs, in scenario order (empty without one); their phase vectors are concatenated
    /// in this order (docs/model.md §2).
    pub fn surfaces(&self) -> &[Irs] {
        match &self.irs {
            Some(one) => std::slice::from_ref(one),
            None => &self.irss,
        }
    }

    /// The access points, in scenario order (at least one).
    pub fn access_points(&self) -> &[AccessPoint] {
        match &self.ap {
            Some(one) => std::slice::from_ref(one),
            None => &self.aps,
        }
    }

    /// The first access point: its carrier sets λ for the IRS's default pitch, and it is the
    /// AP of rate maps (which take one AP).
    pub fn ap(&self) -> &AccessPoint {
        &self.access_points()[0]
    }

    /// The same scenario with other access points, validated again (a derived scenario keeps
    /// its decoded floor plan).
    pub fn with_access_points(&self, mut aps: Vec<AccessPoint>) -> Result<Scenario, FieldError> {
        // One AP as `ap`, so errors name `ap.…` as they would in a document.
        let ap = (aps.len() == 1).then(|| aps.remove(0));
        Scenario {
            ap,
            aps,
            ..self.clone()
        }
        .validated(&kept_raster)
    }

    /// The same scenario with other surfaces, validated again.
    pub fn with_surfaces(&self, mut surfaces: Vec<Irs>) -> Result<Scenario, FieldError> {
        let irs = (surfaces.len() == 1).then(|| surfaces.remove(0));
        Scenario {
            irs,
            irss: surfaces,
            ..self.clone()
        }
        .validated(&kept_raster)
    }

    /// The same scenario with surface `index` replaced by `irs`, validated again (a placement
    /// candidate).
    pub fn with_surface(&self, index: usize, irs: Irs) -> Result<Scenario, FieldError> {
        let mut surfaces = self.surfaces().to_vec();
        *surfaces
            .get_mut(index)
            .ok_or_else(|| FieldError::new("index", "the scenario has no IRS of that index"))? =
            irs;
        self.with_surfaces(surfaces)
    }

    /// The same scenario with access point `index` moved to `position`, validated again.
    pub fn with_ap_at(&self, index: usize, position: [f64; 3]) -> Result<Scenario, FieldError> {
        let mut aps = self.access_points().to_vec();
        aps.get_mut(index)
            .ok_or_else(|| FieldError::new("index", "the scenario has no AP of that index"))?
            .position = position;
        self.with_access_points(aps)
    }

    /// λ = c / f_c (m) of the first AP's carrier.
    pub fn wavelength_m(&self) -> f64 {
        self.access_points()
            .first()
            .map_or(f64::NAN, |ap| SPEED_OF_LIGHT / (ap.carrier_ghz * 1e9))
    }

    fn resolve_defaults(&mut self) {
        if let Some(plan) = &mut self.floor_plan
            && plan.obstacle_height_m.is_none()
        {
            plan.obstacle_height_m = Some(self.room.ceiling_m);
        }
        let lambda = self.wavelength_m();
        for irs in self.irs.iter_mut().chain(self.irss.iter_mut()) {
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

    /// The cell lattice; valid only on a validated scenario.
    pub fn grid(&self) -> Grid {
        let r = &self.room;
        let d = self.grid.resolution_m;
        Grid {
            nx: ((r.x_max - r.x_min) / d).round() as usize + 1,
            ny: ((r.y_max - r.y_min) / d).round() as usize + 1,
            x_min: r.x_min,
            y_min: r.y_min,
            resolution_m: d,
        }
    }

    /// Everything standing on the floor (boxes, walls, the floor plan's occupied pixels), for
    /// blockage and occupancy (docs/model.md §1).
    pub fn obstructions(&self) -> Obstructions {
        Obstructions {
            boxes: self
                .obstacles
                .iter()
                .map(|o| Aabb {
                    lo: [
                        o.center[0] - o.size[0] / 2.0,
                        o.center[1] - o.size[1] / 2.0,
                        0.0,
                    ],
                    hi: [
                        o.center[0] + o.size[0] / 2.0,
                        o.center[1] + o.size[1] / 2.0,
                        o.height_m,
                    ],
                })
                .collect(),
            walls: self
                .walls
                .iter()
                .map(|w| Wall::new(w.from, w.to, w.thickness_m, w.height_m))
                .collect(),
            raster: self.raster.clone(),
        }
    }

    fn validate(&mut self, image: ImageFile) -> Result<(), FieldError> {
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

        self.validate_walls()?;
        // A scenario derived from a validated one (`with_surface`) keeps its decoded raster.
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
        let obstructions = self.obstructions();

        let access_points: Vec<(String, &AccessPoint)> = match (&self.ap, self.aps.as_slice()) {
            (Some(_), [_, ..]) => {
                return err(
                    "aps",
                    "give one access point as `ap` or a list as `aps`, not both",
                );
            }
            (None, []) => {
                return err(
                    "ap",
                    "missing: give the access point as `ap` (or several as `aps`)",
                );
            }
            (Some(one), []) => vec![("ap".to_string(), one)],
            (None, many) => many
                .iter()
                .enumerate()
                .map(|(k, ap)| (format!("aps[{k}]"), ap))
                .collect(),
        };
        if self.aps.len() > MAX_APS {
            return Err(FieldError::new(
                "aps",
                format!("more than {MAX_APS} access points"),
            ));
        }
        for (at, ap) in &access_points {
            let f = |s: &str| format!("{at}.{s}");
            finite_all(&f("position"), &ap.position)?;
            finite(&f("tx_power_dbm"), ap.tx_power_dbm)?;
            finite(&f("noise_dbm"), ap.noise_dbm)?;
            finite(&f("carrier_ghz"), ap.carrier_ghz)?;
            if !(ap.carrier_ghz > 0.0 && ap.carrier_ghz <= 100.0) {
                return err(
                    &f("carrier_ghz"),
                    "must lie in (0, 100] GHz, the 3GPP InF model's range",
                );
            }
            self.inside_room(&f("position"), ap.position)?;
            if obstructions.contains(ap.position) {
                return err(&f("position"), "lies inside an obstacle");
            }
        }

        if self.irs.is_some() && !self.irss.is_empty() {
            return err(
                "irss",
                "give one surface as `irs` or a list as `irss`, not both",
            );
        }
        let surfaces: Vec<(String, &Irs)> = match &self.irs {
            Some(one) => vec![("irs".to_string(), one)],
            None => self
                .irss
                .iter()
                .enumerate()
                .map(|(k, irs)| (format!("irss[{k}]"), irs))
                .collect(),
        };
        if self.irss.len() > MAX_SURFACES {
            return Err(FieldError::new(
                "irss",
                format!("more than {MAX_SURFACES} surfaces"),
            ));
        }
        let (mut total_n, mut total_m) = (0usize, 0usize);
        for (at, irs) in &surfaces {
            self.validate_irs(irs, at, &obstructions)?;
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

        finite("channel.rician_k_db", self.channel.rician_k_db)?;
        if self.channel.rician_k_db.abs() > 60.0 {
            return err("channel.rician_k_db", "must lie in [-60, 60] dB");
        }
        Ok(())
    }

    /// Checks one surface; `at` is its JSON path (`irs` or `irss[k]`).
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
                         surface (for a floor plan, on a pixel edge at origin + k·resolution)",
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
                 the floor plan's occupied pixels",
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

    /// Bytes of the decoded floor plan (one per pixel), which a registry weighs besides the
    /// canonical document (numbers and the floor plan's base64 take about as much parsed as
    /// written).
    pub fn raster_bytes(&self) -> usize {
        self.raster.as_ref().map_or(0, |r| r.occupied.capacity())
    }
}

fn finite(field: &str, v: f64) -> Result<(), FieldError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(FieldError::new(field, "must be a finite number"))
    }
}

fn finite_all(field: &str, v: &[f64]) -> Result<(), FieldError> {
    v.iter().try_for_each(|&x| finite(field, x))
}

#[cfg(test)]
impl Scenario {
    /// A built-in scenario by name, for the model's own tests (the public way to read one is
    /// `irs_answers::scenario`).
    pub(crate) fn builtin(name: &str) -> Option<Scenario> {
        Scenario::builtin_with(name, |_| {}).map(|s| s.expect("built-in scenarios are valid"))
    }

    /// A variant of a built-in scenario: `edit` changes its JSON document first.
    pub(crate) fn builtin_with(
        name: &str,
        edit: impl FnOnce(&mut serde_json::Value),
    ) -> Option<Result<Scenario, FieldError>> {
        let text = match name {
            "paper-single-user" => include_str!("../../../scenarios/paper-single-user.json"),
            "paper-multi-user" => include_str!("../../../scenarios/paper-multi-user.json"),
            "small-test" => include_str!("../../../scenarios/small-test.json"),
            _ => return None,
        };
        let mut document: serde_json::Value = serde_json::from_str(text).expect("JSON");
        edit(&mut document);
        let scenario: Scenario = match serde_json::from_value(document) {
            Ok(s) => s,
            Err(e) => return Some(Err(FieldError::new("$", e))),
        };
        Some(scenario.validated(&kept_raster))
    }

    /// The built-in small floor with a second IRS on its east wall (a test fixture).
    pub(crate) fn small_test_two_surfaces(grouping: Grouping) -> Scenario {
        let name = serde_json::to_value(grouping).expect("groupings serialise");
        Scenario::builtin_with("small-test", |v| {
            let mut first = v.as_object_mut().unwrap().remove("irs").unwrap();
            first["grouping"] = name.clone();
            let second = serde_json::json!({
                "center": [6.0, 2.0, 1.8], "normal": [-1.0, 0.0, 0.0],
                "nx_sub": 3, "nz_sub": 1, "elements_per_sub": 2, "grouping": name,
            });
            v["irss"] = serde_json::json!([first, second]);
        })
        .expect("built in")
        .expect("a valid two-surface variant")
    }

    /// The built-in small floor with its IRS's elements grouped as given (a test fixture).
    pub(crate) fn small_test_grouped(grouping: Grouping) -> Scenario {
        let name = serde_json::to_value(grouping).expect("groupings serialise");
        Scenario::builtin_with("small-test", |v| v["irs"]["grouping"] = name)
            .expect("built in")
            .expect("a valid grouping variant")
    }
}
