//! The scenario's wire form: the JSON document as written, where one access point or one IRS
//! may stand on its own (`ap`, `irs`) or in a list (`aps`, `irss`). The model knows only
//! lists ([`Draft`]); this type is where the two spellings meet, in both directions:
//!
//! * in, a document becomes a draft, and the model's errors (which name `aps[k]` and
//!   `irss[k]`) are renamed to what the document wrote;
//! * out, a scenario becomes its canonical document: one AP as `ap`, one IRS as `irs`, so a
//!   scenario has the same id whichever way it was written.

use crate::route_graph::GraphDocument;
use irs_model::floorplan::FloorPlan;
use irs_model::input::{FieldError, present};
use irs_model::scenario::{
    AccessPoint, ChannelSpec, Draft, GridSpec, ImageFile, Irs, Mru, Obstacle, Room, Scenario, Sru,
    WallSpec, as_written,
};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// A scenario document (docs/scenarios.md). Parsing is strict: an unknown field is an error.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Document {
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    name: Option<String>,
    room: Room,
    grid: GridSpec,
    #[serde(default)]
    obstacles: Vec<Obstacle>,
    /// Left out of the canonical form when empty, so scenarios written before walls existed
    /// keep their ids.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    walls: Vec<WallSpec>,
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    floor_plan: Option<FloorPlan>,
    /// One access point (the paper's set-up) …
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    ap: Option<AccessPoint>,
    /// … or several.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    aps: Vec<AccessPoint>,
    /// One IRS …
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    irs: Option<Irs>,
    /// … or several.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    irss: Vec<Irs>,
    mru: Mru,
    #[serde(default)]
    srus: Vec<Sru>,
    #[serde(default)]
    channel: ChannelSpec,
    /// The route graph the site's robots drive along (crate::route_graph).
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    route_graph: Option<GraphDocument>,
}

impl Document {
    /// Checks the document's own rules (each list written one way), then the model's; the
    /// model's errors name the fields as this document wrote them.
    pub fn validated(self, image: ImageFile) -> Result<Scenario, FieldError> {
        let one_ap = self.ap.is_some();
        let one_irs = self.irs.is_some();
        let access_points = match (self.ap, self.aps) {
            (Some(_), aps) if !aps.is_empty() => {
                return Err(FieldError::new(
                    "aps",
                    "give one access point as `ap` or a list as `aps`, not both",
                ));
            }
            (None, aps) if aps.is_empty() => {
                return Err(FieldError::new(
                    "ap",
                    "missing: give the access point as `ap` (or several as `aps`)",
                ));
            }
            (Some(one), _) => vec![one],
            (None, many) => many,
        };
        let surfaces = match (self.irs, self.irss) {
            (Some(_), irss) if !irss.is_empty() => {
                return Err(FieldError::new(
                    "irss",
                    "give one surface as `irs` or a list as `irss`, not both",
                ));
            }
            (Some(one), _) => vec![one],
            (None, many) => many,
        };
        let draft = Draft {
            name: self.name,
            room: self.room,
            grid: self.grid,
            obstacles: self.obstacles,
            walls: self.walls,
            floor_plan: self.floor_plan,
            access_points,
            surfaces,
            mru: self.mru,
            srus: self.srus,
            channel: self.channel,
        };
        let mut scenario = draft
            .validated(image)
            .map_err(|e| as_written(e, one_ap, one_irs))?;
        if let Some(graph) = self.route_graph {
            scenario.route_graph = Some(Arc::new(graph.validated(&scenario.grid())?));
        }
        Ok(scenario)
    }
}

impl From<&Scenario> for Document {
    /// The canonical document: defaults resolved (the scenario holds them), one AP as `ap`,
    /// one IRS as `irs`.
    fn from(s: &Scenario) -> Document {
        let (ap, aps) = match s.access_points() {
            [one] => (Some(one.clone()), vec![]),
            many => (None, many.to_vec()),
        };
        let (irs, irss) = match s.surfaces() {
            [one] => (Some(one.clone()), vec![]),
            many => (None, many.to_vec()),
        };
        Document {
            name: s.name.clone(),
            room: s.room.clone(),
            grid: s.grid.clone(),
            obstacles: s.obstacles.clone(),
            walls: s.walls.clone(),
            floor_plan: s.floor_plan.clone(),
            ap,
            aps,
            irs,
            irss,
            mru: s.mru.clone(),
            srus: s.srus.clone(),
            channel: s.channel.clone(),
            route_graph: s.route_graph.as_deref().map(GraphDocument::from),
        }
    }
}
