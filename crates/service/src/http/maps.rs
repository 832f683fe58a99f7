//! `/v1/maps`: request a map (built at once when cheap, else as a job answered 202), list the
//! cached ones, read one's body and delete it; and the map acquisition the path, sweep and
//! export handlers share (a map by id, or by the request defining it).

use super::problem::ApiError;
use super::{Body, Page, accepted, heavy, only_query};
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::app::maps::{MapSpec, Obtained};
use crate::app::scenarios::ScenarioRef;
use crate::ids::{MapId, ScenarioId};
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use irs_answers::timing::Timed;
use irs_model::input::present;
use irs_model::phases::PhaseMode;
use irs_model::radiomap::{MapKey, MapKind, MapStats, RadioMap, Unit};
use irs_model::rate::Access;
use irs_model::solver::SolverKind;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::time::Instant;

/// What defines a map: a scenario (registered id or inline document) and the map parameters.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MapRequest {
    #[serde(default, deserialize_with = "present")]
    scenario_id: Option<ScenarioId>,
    #[serde(default, deserialize_with = "present")]
    scenario: Option<serde_json::Map<String, serde_json::Value>>,
    kind: MapKind,
    #[serde(default, deserialize_with = "present")]
    phases: Option<PhaseMode>,
    #[serde(default, deserialize_with = "present")]
    access: Option<Access>,
    #[serde(default, deserialize_with = "present")]
    solver: Option<SolverKind>,
}

#[derive(Debug, Serialize)]
pub(super) struct MapSummary {
    map_id: MapId,
    state: &'static str,
    key: MapKey,
    unit: &'static str,
    stats: MapStats,
    build_seconds: f64,
    href: String,
}

pub(super) fn summary(map: &RadioMap) -> MapSummary {
    let map_id = MapId::of_map(map);
    MapSummary {
        href: map_id.href(),
        map_id,
        state: "ready",
        key: map.key.clone(),
        unit: map.key.unit(),
        stats: map.stats(),
        build_seconds: map.build_seconds,
    }
}

impl MapRequest {
    /// The map this request defines, as the application takes it.
    pub(super) fn spec(self) -> MapSpec {
        MapSpec {
            scenario: ScenarioRef {
                id: self.scenario_id,
                document: self.scenario,
            },
            kind: self.kind,
            phases: self.phases,
            access: self.access,
            solver: self.solver,
        }
    }
}

/// A 200 with the map's summary, or the 202 of the job building it.
fn answer(started: Instant, found: Obtained) -> Response {
    match found {
        Obtained::Ready { map, .. } => Json(Timed::since(started, summary(&map))).into_response(),
        Obtained::Building(job) => accepted(*job),
    }
}

pub(super) async fn request_map(
    State(state): State<App>,
    caller: Caller,
    Body(request): Body<MapRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let found = state.request_map(&caller, request.spec(), "").await?;
    Ok(answer(started, found))
}

#[derive(Serialize)]
pub(super) struct MapList {
    maps: Vec<MapSummary>,
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The cached maps the caller asked for (all of them with authentication off), by id, a page
/// at a time.
pub(super) async fn list_maps(
    State(state): State<App>,
    caller: Caller,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<MapList>, ApiError> {
    let page = Page::of(&query)?;
    let mut entries: Vec<(String, _)> = state
        .list_maps(&caller)
        .await?
        .into_iter()
        .map(|(id, map)| (id.to_string(), map))
        .collect();
    entries.sort_by(|a, b| a.0.cmp(&b.0));
    let (maps, next_cursor) = page.cut(entries, |key, cursor| key > cursor);
    Ok(Json(MapList {
        maps: maps.iter().map(|m| summary(m)).collect(),
        next_cursor,
    }))
}

/// Withdraws the caller's claim on a map, dropping the map with the last claim (the next
/// request for it builds it again). A map being built answers 409 with its job: cancel the
/// job instead.
pub(super) async fn delete_map(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
) -> Result<StatusCode, ApiError> {
    state.delete_map(&caller, &map_id).await?;
    Ok(StatusCode::NO_CONTENT)
}

pub(super) async fn get_map(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    only_query(&query, &["unit"])?;
    let unit = query
        .get("unit")
        .map(|text| text.parse::<Unit>().map_err(|e| Error::invalid("unit", e)))
        .transpose()?;
    let map = state.map(&caller, &map_id).await?;
    let cells = map.grid.cells();
    let bytes = heavy(&state, "map body", cells, move |_| {
        let body = irs_answers::map::body_in(&map, unit.unwrap_or(map.native_unit()))?;
        Ok::<_, Error>(serde_json::to_vec(&Timed::since(started, body)))
    })
    .await??;
    let bytes = bytes.map_err(|e| Error::internal(format!("serialising the map: {e}")))?;
    Ok(([(header::CONTENT_TYPE, "application/json")], bytes).into_response())
}
