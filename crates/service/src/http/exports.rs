//! The map's exports: `image.png` (with a path drawn on it), `nav2-mask` (a Nav2 keep-out or
//! cost mask as YAML + PGM in a tar), `values.npy` (NumPy) and `zone-set` (a VDA 5050 zone
//! set).

use super::problem::ApiError;
use super::{heavy, only_query};
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::ids::MapId;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use irs_answers::export::{self, MaskKind};
use irs_answers::render::{self, RenderOptions};
use irs_answers::vda5050::{self, Header, ZoneParams};
use irs_model::input::{FieldError, parse_finite, parse_point};
use irs_model::planner::{self, PathOptions, PathShape, Threshold};
use irs_model::radiomap::{Progress, Unit};
use std::collections::HashMap;
use std::time::SystemTime;

/// The optional `unit` query parameter.
fn query_unit(query: &HashMap<String, String>) -> Result<Option<Unit>, Error> {
    query
        .get("unit")
        .map(|text| text.parse::<Unit>().map_err(|e| Error::invalid("unit", e)))
        .transpose()
}

/// An optional "x,y" query parameter.
pub(super) fn query_point(
    query: &HashMap<String, String>,
    name: &'static str,
) -> Result<Option<[f64; 2]>, Error> {
    query
        .get(name)
        .map(|text| parse_point(text).map_err(|e| Error::invalid(name, e)))
        .transpose()
}

/// The map as a PNG; with `start` and `goal`, the path at `threshold` (default "max") drawn on it.
pub(super) async fn image(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(
        &query,
        &[
            "threshold",
            "unit",
            "path_shape",
            "start",
            "goal",
            "cell_px",
        ],
    )?;
    let unit = query_unit(&query)?;
    let shape = query
        .get("path_shape")
        .map(|text| {
            text.parse::<PathShape>()
                .map_err(|e| Error::invalid("path_shape", e))
        })
        .transpose()?
        .unwrap_or_default();
    let threshold = match query.get("threshold") {
        None => Threshold::Max,
        Some(text) => text
            .parse::<Threshold>()
            .map_err(|e| Error::invalid("threshold", e))?,
    };
    let path_ends = match (query_point(&query, "start")?, query_point(&query, "goal")?) {
        (Some(s), Some(g)) => Some((s, g)),
        (None, None) => None,
        (start, _) => {
            return Err(Error::invalid(
                if start.is_none() { "start" } else { "goal" },
                "give both start and goal, or neither",
            )
            .into());
        }
    };
    let cell_px = query
        .get("cell_px")
        .map(|text| {
            text.parse::<usize>()
                .ok()
                .filter(|px| (1..=render::MAX_CELL_PX).contains(px))
                .ok_or_else(|| {
                    Error::limit_exceeded(
                        "cell_px",
                        render::MAX_CELL_PX as u64,
                        format!(
                            "must be a whole number of pixels from 1 to {}",
                            render::MAX_CELL_PX
                        ),
                    )
                })
        })
        .transpose()?;
    let (map, scenario) = state.map_with_scenario(&caller, &map_id).await?;
    // Rendering touches every pixel (up to 4096² of them), so it is always a heavy query.
    let render = move |_: &Progress| -> Result<Option<Vec<u8>>, FieldError> {
        let unit = unit.unwrap_or(map.native_unit());
        let options = match path_ends {
            Some((s, g)) => RenderOptions::for_path(
                &map,
                &planner::plan(
                    &map,
                    unit,
                    PathOptions {
                        shape,
                        tolerance_m: 0.0,
                    },
                    s,
                    g,
                    threshold,
                    1.0,
                )?,
            ),
            None => RenderOptions {
                unit: Some(unit),
                threshold: match threshold {
                    Threshold::Value(t) => Some(t),
                    Threshold::Max => None,
                },
                ..RenderOptions::default()
            },
        };
        let options = RenderOptions { cell_px, ..options };
        render::png(&map, &scenario, &options)
    };
    let bytes = state
        .queries()
        .run("picture", render)
        .await??
        .ok_or_else(|| {
            Error::limit_exceeded(
                "cell_px",
                render::MAX_SIDE_PX as u64,
                format!(
                    "the picture would exceed {} pixels a side",
                    render::MAX_SIDE_PX
                ),
            )
        })?;
    Ok(([(header::CONTENT_TYPE, "image/png")], bytes).into_response())
}

/// A Nav2 mask of the map at `threshold` (keep-out by default, or `mask=cost` with an optional
/// `best`): its YAML and PGM in one tar archive.
pub(super) async fn nav2_mask(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(&query, &["threshold", "unit", "mask", "best"])?;
    let unit = query_unit(&query)?;
    let number = |name: &'static str| {
        query
            .get(name)
            .map(|text| parse_finite(text).map_err(|e| Error::invalid(name, e)))
            .transpose()
    };
    let threshold = number("threshold")?
        .ok_or_else(|| Error::invalid("threshold", "the threshold query parameter is required"))?;
    let best = number("best")?;
    let kind = query
        .get("mask")
        .map(|text| {
            text.parse::<MaskKind>()
                .map_err(|e| Error::invalid("mask", e))
        })
        .transpose()?
        .unwrap_or_default();
    let map = state.map(&caller, &map_id).await?;
    let cells = map.grid.cells();
    let archive = heavy(&state, "mask export", cells, move |_| {
        let unit = unit.unwrap_or(map.native_unit());
        export::nav2_mask(&map, unit, kind, threshold, best).map(|mask| mask.tar())
    })
    .await?
    .map_err(|e| Error::invalid(e.field, e.reason))?;
    let disposition = format!("attachment; filename=\"{map_id}-{}.tar\"", kind.stem());
    Ok((
        [
            (header::CONTENT_TYPE, "application/x-tar".to_string()),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        archive,
    )
        .into_response())
}

/// The media type of a VDA 5050 zone set.
const VDA5050_ZONE_SET_JSON: &str = "application/vnd.vda5050.zone-set+json";

/// The map at `threshold` as a VDA 5050 zone set (BLOCKED below it, PENALTY in
/// `penalty_band` above it).
pub(super) async fn zone_set(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(
        &query,
        &[
            "threshold",
            "unit",
            "penalty_band",
            "penalty_levels",
            "zone_set_id",
            "vda_map_id",
            "header_id",
            "manufacturer",
            "serial_number",
        ],
    )?;
    let unit = query_unit(&query)?;
    let number = |name: &'static str| {
        query
            .get(name)
            .map(|text| parse_finite(text).map_err(|e| Error::invalid(name, e)))
            .transpose()
    };
    let whole = |name: &'static str| {
        query
            .get(name)
            .map(|text| {
                text.parse::<u32>().map_err(|_| {
                    Error::invalid(name, "must be a whole number from 0 to 4294967295")
                })
            })
            .transpose()
    };
    let threshold = number("threshold")?
        .ok_or_else(|| Error::invalid("threshold", "the threshold query parameter is required"))?;
    let params = ZoneParams {
        header: Header {
            header_id: whole("header_id")?.unwrap_or(0),
            manufacturer: query.get("manufacturer").cloned().unwrap_or_default(),
            serial_number: query.get("serial_number").cloned().unwrap_or_default(),
            map_id: query.get("vda_map_id").cloned(),
        },
        zone_set_id: query.get("zone_set_id").cloned(),
        penalty_band: number("penalty_band")?,
        penalty_levels: whole("penalty_levels")?.map(|n| n as usize),
    };
    params
        .validate()
        .map_err(|e| Error::invalid(vda_field(&e.field), e.reason))?;
    let map = state.map(&caller, &map_id).await?;
    let cells = map.grid.cells();
    let zones = heavy(&state, "zone set", cells, move |_| {
        let unit = unit.unwrap_or(map.native_unit());
        let zones = vda5050::zone_set(&map, unit, threshold, &params, SystemTime::now())?;
        Ok::<_, FieldError>(serde_json::to_vec(&zones).expect("a zone set serialises"))
    })
    .await?
    .map_err(|e| Error::invalid(vda_field(&e.field), e.reason))?;
    Ok(([(header::CONTENT_TYPE, VDA5050_ZONE_SET_JSON)], zones).into_response())
}

/// A zone set parameter's query name (the header's `map_id` is `vda_map_id`).
fn vda_field(field: &str) -> String {
    match field {
        "map_id" => "vda_map_id".to_string(),
        other => other.to_string(),
    }
}

/// The map's values as a NumPy `.npy` (float32, shape (nx, ny), NaN where occupied).
pub(super) async fn values_npy(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(&query, &["unit"])?;
    let unit = query_unit(&query)?;
    let map = state.map(&caller, &map_id).await?;
    let cells = map.grid.cells();
    let bytes = heavy(&state, "values export", cells, move |_| {
        export::npy(&map, unit.unwrap_or(map.native_unit()))
    })
    .await?
    .map_err(|e| Error::invalid(e.field, e.reason))?;
    let disposition = format!("attachment; filename=\"{map_id}.npy\"");
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (header::CONTENT_DISPOSITION, disposition),
        ],
        bytes,
    )
        .into_response())
}
