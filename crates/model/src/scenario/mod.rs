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
pub mod route_graph;
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
use crate::input::FieldError;
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

/// An error of the checks (which name the lists `aps[k]` and `irss[k]`) as a document names it
/// that writes its one AP on its own as `ap` (`lone_ap`) and its one IRS as `irs` (`lone_irs`).
pub fn as_written(e: FieldError, lone_ap: bool, lone_irs: bool) -> FieldError {
    let e = if lone_ap {
        e.renamed("aps[0]", "ap")
    } else {
        e
    };
    if lone_irs {
        e.renamed("irss[0]", "irs")
    } else {
        e
    }
}

/// A scenario as given, before its checks: the pieces of a floor, with the access points and
/// the surfaces as lists. The answers crate's document reads one from JSON (where one AP or
/// IRS may also be written on its own); [`Draft::validated`] makes it a [`Scenario`].
#[derive(Debug, Clone, PartialEq)]
pub struct Draft {
    /// Free-text label.
    pub name: Option<String>,
    /// The floor's rectangle and height.
    pub room: Room,
    /// The grid spacing.
    pub grid: GridSpec,
    /// Boxes standing on the floor.
    pub obstacles: Vec<Obstacle>,
    /// Straight walls at any angle (what a CAD plan gives).
    pub walls: Vec<WallSpec>,
    /// A ROS occupancy-grid map of the floor (see [`crate::floorplan`]).
    pub floor_plan: Option<FloorPlan>,
    /// The access points, each on its own channel (docs/model.md §3); at least one. Errors
    /// name them `aps[k]`.
    pub access_points: Vec<AccessPoint>,
    /// The IRSs, each with its own pose, sub-surfaces and grouping (docs/model.md §2); their
    /// phase vectors are concatenated in this order. Errors name them `irss[k]`.
    pub surfaces: Vec<Irs>,
    /// The mobile robot.
    pub mru: Mru,
    /// The static robots (K ≥ 0; rate maps need at least one).
    pub srus: Vec<Sru>,
    /// The channel's parameters.
    pub channel: ChannelSpec,
}

impl Draft {
    /// Resolves defaults, checks every field (each error names its path in a document that
    /// writes the lists as `aps` and `irss`), mounts the surfaces that ask for it and decodes
    /// the floor plan: its image file's bytes come from `image`, which reads the text of
    /// `floor_plan.image` (the answers crate decodes the document's base64).
    pub fn validated(self, image: ImageFile) -> Result<Scenario, FieldError> {
        Scenario {
            name: self.name,
            room: self.room,
            grid: self.grid,
            obstacles: self.obstacles,
            walls: self.walls,
            floor_plan: self.floor_plan,
            raster: None,
            access_points: self.access_points,
            surfaces: self.surfaces,
            mru: self.mru,
            srus: self.srus,
            channel: self.channel,
            route_graph: None,
        }
        .checked(image)
    }
}

/// A scenario that has passed its checks ([`Draft::validated`]): every field finite and
/// consistent. Its JSON document (parsing, canonical form, id) is the answers crate's
/// (`irs_answers::scenario`).
#[derive(Debug, Clone, PartialEq)]
pub struct Scenario {
    /// Free-text label; part of the document (and so of its hash).
    pub name: Option<String>,
    /// The floor's rectangle and height.
    pub room: Room,
    /// The grid spacing.
    pub grid: GridSpec,
    /// Boxes standing on the floor.
    pub obstacles: Vec<Obstacle>,
    /// Straight walls at any angle.
    pub walls: Vec<WallSpec>,
    /// A ROS occupancy-grid map of the floor (see [`crate::floorplan`]).
    pub floor_plan: Option<FloorPlan>,
    /// The decoded floor plan, made once at validation and shared by every map built from it.
    raster: Option<Arc<Raster>>,
    /// At least one; read with [`Scenario::access_points`].
    access_points: Vec<AccessPoint>,
    /// Read with [`Scenario::surfaces`].
    surfaces: Vec<Irs>,
    /// The mobile robot.
    pub mru: Mru,
    /// The static robots.
    pub srus: Vec<Sru>,
    /// The channel's parameters.
    pub channel: ChannelSpec,
    /// The route graph the site's robots drive along, if one is attached (the answers crate
    /// reads and checks it: its formats are wire formats).
    pub route_graph: Option<Arc<route_graph::RouteGraph>>,
}

impl Scenario {
    /// Every way to make a scenario ends here: defaults resolved, every field checked, the
    /// floor plan decoded (a scenario derived from a validated one keeps its decoded raster,
    /// so `image` is not called again) and the surfaces mounted.
    fn checked(mut self, image: ImageFile) -> Result<Scenario, FieldError> {
        self.resolve_defaults();
        self.validate(image)?;
        Ok(self)
    }

    /// [`Scenario::checked`] for a scenario derived from a validated one, whose errors name
    /// the fields as its canonical document does (one AP as `ap`, one IRS as `irs`).
    fn rechecked(self) -> Result<Scenario, FieldError> {
        let one_ap = self.access_points.len() == 1;
        let one_irs = self.surfaces.len() == 1;
        self.checked(&kept_raster)
            .map_err(|e| as_written(e, one_ap, one_irs))
    }

    /// The IRSs, in scenario order (empty without one); their phase vectors are concatenated
    /// in this order (docs/model.md §2).
    pub fn surfaces(&self) -> &[Irs] {
        &self.surfaces
    }

    /// The access points, in scenario order (at least one).
    pub fn access_points(&self) -> &[AccessPoint] {
        &self.access_points
    }

    /// The path of access point `k`'s fields in the scenario's canonical document, for errors
    /// found after validation: `ap` when there is one (the canonical form writes one AP on its
    /// own), `aps[k]` otherwise.
    pub fn ap_field(&self, k: usize) -> String {
        if self.access_points.len() == 1 {
            "ap".to_string()
        } else {
            format!("aps[{k}]")
        }
    }

    /// The first access point: its carrier sets λ for the IRS's default pitch, and it is the
    /// AP of rate maps (which take one AP).
    pub fn ap(&self) -> &AccessPoint {
        &self.access_points[0]
    }

    /// The same scenario with other access points, validated again (a derived scenario keeps
    /// its decoded floor plan).
    pub fn with_access_points(&self, aps: Vec<AccessPoint>) -> Result<Scenario, FieldError> {
        Scenario {
            access_points: aps,
            ..self.clone()
        }
        .rechecked()
    }

    /// The same scenario with other surfaces, validated again.
    pub fn with_surfaces(&self, surfaces: Vec<Irs>) -> Result<Scenario, FieldError> {
        Scenario {
            surfaces,
            ..self.clone()
        }
        .rechecked()
    }

    /// The same scenario with surface `index` replaced by `irs`, validated again (a placement
    /// candidate).
    pub fn with_surface(&self, index: usize, irs: Irs) -> Result<Scenario, FieldError> {
        let mut surfaces = self.surfaces.clone();
        *surfaces
            .get_mut(index)
            .ok_or_else(|| FieldError::new("index", "the scenario has no IRS of that index"))? =
            irs;
        self.with_surfaces(surfaces)
    }

    /// The same scenario with access point `index` moved to `position`, validated again.
    pub fn with_ap_at(&self, index: usize, position: [f64; 3]) -> Result<Scenario, FieldError> {
        let mut aps = self.access_points.clone();
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

    /// Bytes of the decoded floor plan (one per pixel: its clearance), which a registry weighs besides the
    /// canonical document (numbers and the floor plan's base64 take about as much parsed as
    /// written).
    pub fn raster_bytes(&self) -> usize {
        self.raster.as_ref().map_or(0, |r| r.heap_bytes())
    }
}

#[cfg(test)]
impl Scenario {
    /// A built-in scenario by name, for the model's own tests (the public way to read one is
    /// `irs_answers::scenario`).
    pub(crate) fn builtin(name: &str) -> Option<Scenario> {
        Scenario::builtin_with(name, |_| {}).map(|s| s.expect("built-in scenarios are valid"))
    }

    /// A variant of a built-in scenario: `edit` changes its JSON document first. The
    /// document is read piece by piece (the answers crate's parser is the real one), `ap` and
    /// `irs` as one-element lists.
    pub(crate) fn builtin_with(
        name: &str,
        edit: impl FnOnce(&mut serde_json::Value),
    ) -> Option<Result<Scenario, FieldError>> {
        use serde_json::Value;
        let text = match name {
            "paper-single-user" => include_str!("../../../../scenarios/paper-single-user.json"),
            "paper-multi-user" => include_str!("../../../../scenarios/paper-multi-user.json"),
            "small-test" => include_str!("../../../../scenarios/small-test.json"),
            _ => return None,
        };
        let mut document: Value = serde_json::from_str(text).expect("JSON");
        edit(&mut document);
        let doc = document.as_object_mut().expect("an object");
        fn part<T: serde::de::DeserializeOwned>(v: Option<Value>) -> Option<T> {
            v.filter(|v| !v.is_null())
                .map(|v| serde_json::from_value(v).expect("a valid part"))
        }
        let list = |one: &str, many: &str, doc: &mut serde_json::Map<String, Value>| {
            let one = doc.remove(one).filter(|v| !v.is_null());
            let many = doc.remove(many).unwrap_or(Value::Array(vec![]));
            let mut items = many.as_array().cloned().unwrap_or_default();
            items.extend(one);
            Value::Array(items)
        };
        let aps = list("ap", "aps", doc);
        let irss = list("irs", "irss", doc);
        let draft = Draft {
            name: part(doc.remove("name")),
            room: part(doc.remove("room")).expect("a room"),
            grid: part(doc.remove("grid")).expect("a grid"),
            obstacles: part(doc.remove("obstacles")).unwrap_or_default(),
            walls: part(doc.remove("walls")).unwrap_or_default(),
            floor_plan: part(doc.remove("floor_plan")),
            access_points: part(Some(aps)).unwrap_or_default(),
            surfaces: part(Some(irss)).unwrap_or_default(),
            mru: part(doc.remove("mru")).expect("an mru"),
            srus: part(doc.remove("srus")).unwrap_or_default(),
            channel: part(doc.remove("channel")).unwrap_or_default(),
        };
        assert!(doc.is_empty(), "unknown fields {doc:?}");
        Some(draft.validated(&kept_raster))
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
