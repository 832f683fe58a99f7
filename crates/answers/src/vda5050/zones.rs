//! The radio map at a threshold as a VDA 5050 `zoneSet` (`json_schemas/zoneSet.schema`), for
//! masters and robots that plan their own routes inside zones:
//!
//! * **BLOCKED** where a free cell's value is below the threshold (or has none: a rate map's
//!   cell where no configuration serves every static robot). Occupied cells are left to the
//!   robot's own map;
//! * optionally **PENALTY** where a free cell meets the threshold by less than `penalty_band`:
//!   the penalty 1 − (v − threshold)/band, rounded up to one of `penalty_levels` steps, as
//!   nested zones — the zone of factor k/L covers every cell whose penalty is at least k/L, and
//!   VDA 5050 §6.4.4 resolves overlapping PENALTY zones by their highest factor.
//!
//! Zones are polygons around whole cells ([`irs_model::outline`]): simple, hole-free and
//! counterclockwise as §7.6 requires, covering every cell of their set and adding only what
//! holes and corner-touching cells need (never shrinking a BLOCKED zone), clipped to the room.

use super::{Header, VERSION, check_text, timestamp};
use crate::scenario::hash_hex;
use irs_model::input::FieldError;
use irs_model::outline::{Polygon, outline};
use irs_model::radiomap::{RadioMap, Unit};
use serde::Serialize;
use std::time::SystemTime;

/// Most penalty levels a zone set may have: each is a set of zones of its own.
pub const MAX_PENALTY_LEVELS: usize = 10;

/// Penalty levels when `penalty_band` is given without them.
pub const DEFAULT_PENALTY_LEVELS: usize = 4;

/// What the master decides and the map does not.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ZoneParams {
    /// The header and the map's id (`zoneSet.mapId`; default `map`).
    pub header: Header,
    /// `zoneSetId`; by default a hash of the map, the threshold, its unit and the penalties, so
    /// the same zones have the same id and other zones another (a zone set's content must not
    /// change under its id, §6.4.2).
    pub zone_set_id: Option<String>,
    /// Width (in the threshold's unit) of the band above the threshold that gets PENALTY
    /// zones; none without it.
    pub penalty_band: Option<f64>,
    /// Steps of the penalty factor (1 to [`MAX_PENALTY_LEVELS`]; default
    /// [`DEFAULT_PENALTY_LEVELS`]).
    pub penalty_levels: Option<usize>,
}

/// A VDA 5050 `zoneSet` message.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
pub struct ZoneSet {
    header_id: u32,
    timestamp: String,
    version: &'static str,
    manufacturer: String,
    serial_number: String,
    zone_set: Zones,
}

impl ZoneSet {
    /// How many zones of each type: (BLOCKED, PENALTY).
    pub fn counts(&self) -> (usize, usize) {
        let blocked = self
            .zone_set
            .zones
            .iter()
            .filter(|z| z.zone_type == ZoneType::Blocked)
            .count();
        (blocked, self.zone_set.zones.len() - blocked)
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
struct Zones {
    map_id: String,
    zone_set_id: String,
    zone_set_descriptor: String,
    zones: Vec<Zone>,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "SCREAMING_SNAKE_CASE")]
enum ZoneType {
    Blocked,
    Penalty,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "camelCase")]
struct Zone {
    zone_id: String,
    zone_type: ZoneType,
    zone_descriptor: String,
    vertices: Vec<Vertex>,
    #[serde(skip_serializing_if = "Option::is_none")]
    penalty_factor: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
struct Vertex {
    x: f64,
    y: f64,
}

fn vertices(polygon: Polygon) -> Vec<Vertex> {
    polygon.into_iter().map(|[x, y]| Vertex { x, y }).collect()
}

impl ZoneParams {
    /// Checks the parameters; errors name the query's fields.
    pub fn validate(&self) -> Result<(), FieldError> {
        self.header.validate("")?;
        check_text("zone_set_id", self.zone_set_id.as_deref())?;
        if let Some(band) = self.penalty_band
            && !(band.is_finite() && band > 0.0)
        {
            return Err(FieldError::new(
                "penalty_band",
                "must be a finite number > 0 (in the threshold's unit)",
            ));
        }
        match self.penalty_levels {
            Some(_) if self.penalty_band.is_none() => Err(FieldError::new(
                "penalty_levels",
                "applies only with a penalty_band",
            )),
            Some(levels) if !(1..=MAX_PENALTY_LEVELS).contains(&levels) => Err(FieldError::new(
                "penalty_levels",
                format!("must lie in 1..={MAX_PENALTY_LEVELS}"),
            )),
            _ => Ok(()),
        }
    }
}

/// The zones of `map` at `threshold` (in `unit`), sent at `now`. Errors name the field.
pub fn zone_set(
    map: &RadioMap,
    unit: Unit,
    threshold: f64,
    params: &ZoneParams,
    now: SystemTime,
) -> Result<ZoneSet, FieldError> {
    params.validate()?;
    if !threshold.is_finite() {
        return Err(FieldError::new("threshold", "must be a finite number"));
    }
    let values = map.values_in(unit)?;
    let free = |k: usize| !map.occupied[k];
    let blocked: Vec<bool> = (0..values.len())
        .map(|k| free(k) && (values[k] < threshold || values[k].is_nan()))
        .collect();
    let mut zones: Vec<Zone> = outline(&map.grid, &blocked)
        .into_iter()
        .enumerate()
        .map(|(k, polygon)| Zone {
            zone_id: format!("blocked-{k}"),
            zone_type: ZoneType::Blocked,
            zone_descriptor: format!("below {threshold} {}", unit.symbol()),
            vertices: vertices(polygon),
            penalty_factor: None,
        })
        .collect();
    let levels = params.penalty_levels.unwrap_or(DEFAULT_PENALTY_LEVELS);
    if let Some(band) = params.penalty_band {
        for level in 1..=levels {
            let factor = level as f64 / levels as f64;
            // Penalty ≥ factor ⇔ v < threshold + band·(1 − (level − 1)/levels).
            let below = threshold + band * (1.0 - (level - 1) as f64 / levels as f64);
            let weak: Vec<bool> = (0..values.len())
                .map(|k| free(k) && values[k] >= threshold && values[k] < below)
                .collect();
            zones.extend(
                outline(&map.grid, &weak)
                    .into_iter()
                    .enumerate()
                    .map(|(k, polygon)| Zone {
                        zone_id: format!("penalty-{level}-{k}"),
                        zone_type: ZoneType::Penalty,
                        zone_descriptor: format!(
                            "at most {below} {} (penalty {level}/{levels})",
                            unit.symbol()
                        ),
                        vertices: vertices(polygon),
                        penalty_factor: Some(factor),
                    }),
            );
        }
    }
    let map_id = params
        .header
        .map_id
        .clone()
        .unwrap_or_else(|| "map".to_string());
    let band = params
        .penalty_band
        .map_or("none".to_string(), |b| format!("{b} in {levels} levels"));
    let zone_set_id = params.zone_set_id.clone().unwrap_or_else(|| {
        hash_hex(format!("{} {threshold} {} {band}", map.id, unit.name()).as_bytes())
    });
    Ok(ZoneSet {
        header_id: params.header.header_id,
        timestamp: timestamp(now),
        version: VERSION,
        manufacturer: params.header.manufacturer.clone(),
        serial_number: params.header.serial_number.clone(),
        zone_set: Zones {
            map_id,
            zone_set_id,
            zone_set_descriptor: format!(
                "irs-planner: threshold {threshold} {}, penalty band {band}",
                unit.symbol()
            ),
            zones,
        },
    })
}
