//! The scenario: one JSON document describing a floor, its obstacles, the AP, the optional IRS,
//! the mobile robot (MRU) and the static robots (SRUs) — docs/model.md §1.
//!
//! Parsing is strict (unknown fields are an error) and every check names the offending field by
//! its JSON path, so a fleet manager can fix a document without reading code. Defaults the spec
//! fixes (`sub_pitch_m = λ/2`, `grouping = coherent`, `rician_k_db = 3`) are resolved at parse
//! time, so the canonical form — and therefore the content hash — is the same whether a default
//! was written out or omitted.
//!
//! This module holds the scenario and its accessors; [`parts`] the pieces a document is made
//! of (room, obstacles, walls, APs, IRSs, robots, channel), [`grid`] the cell lattice and
//! `validate` the checks, one concern per function.

mod grid;
mod mount;
pub use mount::MAX_MOUNT_WITHIN_M;
pub mod parts;
mod validate;

pub use grid::Grid;
pub use parts::{
    AccessPoint, ChannelSpec, GridSpec, Grouping, Irs, Mru, Obstacle, PathLossModel, Room, Sru,
    WallSpec,
};

use crate::floorplan::FloorPlan;
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
/// Widest channel (MHz) a throughput is computed for: beyond 802.11ad's 2.16 GHz channels.
pub const MAX_BANDWIDTH_MHZ: f64 = 10_000.0;
/// Largest antenna gain (dBi) accepted, either sign: a dish's gain, far beyond an indoor AP's.
pub const MAX_ANTENNA_GAIN_DBI: f64 = 50.0;
/// Largest fade margin (dB) accepted.
pub const MAX_FADE_MARGIN_DB: f64 = 60.0;
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
    /// The floor's rectangle and height.
    pub room: Room,
    /// The grid spacing.
    pub grid: GridSpec,
    /// Boxes standing on the floor.
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
    /// The mobile robot.
    pub mru: Mru,
    /// The static robots (K ≥ 0; rate maps need at least one).
    #[serde(default)]
    pub srus: Vec<Sru>,
    /// The channel's parameters.
    #[serde(default)]
    pub channel: ChannelSpec,
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

    /// The JSON path of access point `k` in the document (`ap` or `aps[k]`), for errors that
    /// name one of its fields.
    pub fn ap_field(&self, k: usize) -> String {
        if self.ap.is_some() {
            "ap".to_string()
        } else {
            format!("aps[{k}]")
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

    /// Bytes of the decoded floor plan (one per pixel), which a registry weighs besides the
    /// canonical document (numbers and the floor plan's base64 take about as much parsed as
    /// written).
    pub fn raster_bytes(&self) -> usize {
        self.raster.as_ref().map_or(0, |r| r.occupied.capacity())
    }
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
            "paper-single-user" => include_str!("../../../../scenarios/paper-single-user.json"),
            "paper-multi-user" => include_str!("../../../../scenarios/paper-multi-user.json"),
            "small-test" => include_str!("../../../../scenarios/small-test.json"),
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
