//! The map use case: maps built under their ids ([`map_id`], [`build`]) and the body that
//! `irs-planner map` prints and `GET /v1/maps/{id}` returns.

use crate::scenario::{ScenarioDocument, hash_hex};
use irs_model::input::FieldError;
use irs_model::placement::Naming;
use irs_model::radiomap::{
    self, Cancelled, CertificateSummary, ClosedPassage, MapKey, MapStats, Progress, RadioMap, Unit,
};
use irs_model::scenario::{Grid, Scenario};
use serde::Serialize;
use std::borrow::Cow;

/// The JSON body of a map (CLI `map` and `GET /v1/maps/{id}`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapBody<'a> {
    /// The map's id ([`map_id`] of `key`).
    pub map_id: String,
    /// What defines the map.
    pub key: MapKey,
    /// The symbol of the unit of `values`: the map's own, `dB` (gain maps) or `bit/s/Hz`
    /// (rate maps), unless another was asked for ([`body_in`]).
    pub unit: &'static str,
    /// The grid `values` are laid on (room bounds, Δ, nx × ny).
    pub grid: Grid,
    /// Cell counts and the values' min, max, mean and median.
    pub stats: MapStats,
    /// The passages the conservative occupancy closes, largest first (at most
    /// [`radiomap::passages::MAX_LISTED`]; `stats.closed_passages` counts them all): where to
    /// refine the grid.
    pub closed_passages: Vec<ClosedPassage>,
    /// values[i][j] is the cell at (x_min + i·Δ, y_min + j·Δ); null where occupied (or, on rate
    /// maps, where no configuration serves every SRU).
    pub values: Rows<'a>,
    /// Rate maps: the certificate summary, in the unit of `values`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub certificate: Option<CertificateSummary>,
    /// Rate maps: the SDR upper bound per cell, laid out like `values`, in their unit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub upper_bound: Option<Rows<'a>>,
    /// Gain maps of several APs: the AP serving each cell (the strongest), laid out like
    /// `values`, null where occupied.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub serving_ap: Option<ServingRows>,
}

/// The serving AP per cell, written as rows of the grid like [`Rows`], null where occupied.
#[derive(Debug, Clone, PartialEq)]
pub struct ServingRows {
    serving: Vec<Option<usize>>,
    ny: usize,
}

impl Serialize for ServingRows {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.serving.chunks(self.ny))
    }
}

/// Flat per-cell data written as rows of the grid (`[i][j]`), null where not finite, straight
/// from the map's own vector: a copy as nested vectors was a quarter of `irs-planner map`'s
/// time on a million cells.
#[derive(Debug, Clone, PartialEq)]
pub struct Rows<'a> {
    data: Cow<'a, [f64]>,
    ny: usize,
}

impl Rows<'_> {
    /// The value of cell (i, j), `None` where it is not finite (written as null).
    pub fn get(&self, i: usize, j: usize) -> Option<f64> {
        Some(self.data[i * self.ny + j]).filter(|v| v.is_finite())
    }
}

impl Serialize for Rows<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        struct Row<'r>(&'r [f64]);
        impl Serialize for Row<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.collect_seq(self.0.iter().map(|v| v.is_finite().then_some(*v)))
            }
        }
        s.collect_seq(self.data.chunks(self.ny).map(Row))
    }
}

/// The map's body.
pub fn body(map: &RadioMap) -> MapBody<'_> {
    body_in(map, map.native_unit()).expect("a map answers its own unit")
}

/// The map's body with its values and statistics in `unit` ([`RadioMap::values_in`]: a gain
/// map answers every unit, a rate map `bps_hz` and `mbps`); errors name `unit`.
pub fn body_in(map: &RadioMap, unit: Unit) -> Result<MapBody<'_>, FieldError> {
    let values = map.values_in(unit)?;
    let serving_ap =
        (map.links.len() > 1 && map.key.kind == radiomap::MapKind::Gain).then(|| ServingRows {
            serving: (0..map.grid.cells())
                .map(|c| (!map.occupied[c]).then(|| map.serving_ap(c)))
                .collect(),
            ny: map.grid.ny,
        });
    // A rate map's bound and certificate are rates too: in Mbit/s when the values are.
    let scale = match (map.key.kind, unit) {
        (radiomap::MapKind::Rate, Unit::Mbps) => map.links[0].bandwidth_mhz.unwrap_or(f64::NAN),
        _ => 1.0,
    };
    let certificate = map.certificate_summary().map(|c| CertificateSummary {
        median_gap: c.median_gap.map(|g| g * scale),
        mean_gap: c.mean_gap.map(|g| g * scale),
        max_gap: c.max_gap.map(|g| g * scale),
        ..c
    });
    let upper_bound = map.upper_bound().map(|bound| {
        let bound = if scale == 1.0 {
            Cow::Borrowed(bound)
        } else {
            Cow::Owned(bound.iter().map(|b| b * scale).collect())
        };
        rows(map, bound)
    });
    Ok(MapBody {
        map_id: map.id.clone(),
        key: map.key.clone(),
        unit: unit.symbol(),
        grid: map.grid,
        stats: map.stats_of(&values),
        closed_passages: map.closed_passages.listed.clone(),
        values: rows(map, values),
        certificate,
        upper_bound,
        serving_ap,
    })
}

fn rows<'a>(map: &RadioMap, data: Cow<'a, [f64]>) -> Rows<'a> {
    Rows {
        data,
        ny: map.grid.ny,
    }
}

/// The map id of a key: the first 128 bits of SHA-256 over the key's JSON, in hex (the key's
/// fields in declaration order; the model version left out at 1).
pub fn map_id(key: &MapKey) -> String {
    hash_hex(
        serde_json::to_string(key)
            .expect("keys serialise")
            .as_bytes(),
    )
}

/// Builds the map a key defines, named by its id ([`map_id`]).
pub fn build(
    scenario: &Scenario,
    key: &MapKey,
    progress: &Progress,
) -> Result<RadioMap, Cancelled> {
    radiomap::build(scenario, key, map_id(key), progress)
}

/// [`build`], resuming a rate map from the rows `checkpoint` holds and recording there the
/// rows it solves ([`radiomap::build_resuming`]).
pub fn build_resuming(
    scenario: &Scenario,
    key: &MapKey,
    progress: &Progress,
    checkpoint: &radiomap::Checkpoint,
) -> Result<RadioMap, Cancelled> {
    radiomap::build_resuming(scenario, key, map_id(key), progress, checkpoint)
}

/// The ids every answer uses: scenario ids and map ids as content hashes of their documents.
pub struct ContentIds;

impl Naming for ContentIds {
    fn scenario_id(&self, scenario: &Scenario) -> String {
        scenario.content_hash()
    }

    fn scenario_ids(&self, scenarios: &[&Scenario]) -> Vec<String> {
        crate::scenario::content_hashes(scenarios)
    }

    fn map_id(&self, key: &MapKey) -> String {
        map_id(key)
    }
}
