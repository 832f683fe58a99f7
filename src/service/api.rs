//! HTTP handlers and the route table (the contract is `openapi.yaml`). Handlers translate
//! between JSON and the engine; all physics lives in the library modules.

use super::AppState;
use super::cache::ScenarioSummary;
use super::errors::{ApiError, parse_json};
use super::jobs::{Job, JobView, MapRequestOutcome, PlacementOutcome, Work};
use crate::export::{self, MaskKind};
use crate::input::{FieldError, parse_finite, parse_point, present};
use crate::montecarlo::{self, CheckedPath};
use crate::phases::PhaseMode;
use crate::placement::{self, Candidates, Objective, PlacementAnswer, Search, What};
use crate::planner::{self, SweepAnswer, Threshold};
use crate::radiomap::{MapKey, MapKind, MapStats, RadioMap};
use crate::rate::Access;
use crate::render::{self, RenderOptions};
use crate::scenario::Scenario;
use crate::solver::SolverKind;
use crate::timing::Timed;
use axum::extract::{FromRequest, Path, Query, Request, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, delete, get, post};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// Every route: path, methods, handler. The router is built from this table and a test checks
/// it against `openapi.yaml`.
pub fn route_table() -> Vec<(
    &'static str,
    &'static [&'static str],
    MethodRouter<AppState>,
)> {
    vec![
        ("/", &["get"], get(super::viewer::index)),
        ("/viewer/viewer.js", &["get"], get(super::viewer::script)),
        ("/viewer/viewer.css", &["get"], get(super::viewer::style)),
        ("/healthz", &["get"], get(healthz)),
        ("/readyz", &["get"], get(readyz)),
        ("/version", &["get"], get(version)),
        ("/metrics", &["get"], get(metrics_text)),
        (
            "/v1/scenarios",
            &["get", "post"],
            get(list_scenarios).post(register_scenario),
        ),
        (
            "/v1/scenarios/{scenario_id}",
            &["get", "delete"],
            get(get_scenario).delete(delete_scenario),
        ),
        (
            "/v1/maps",
            &["get", "post"],
            get(list_maps).post(request_map),
        ),
        (
            "/v1/maps/{map_id}",
            &["get", "delete"],
            get(get_map).delete(delete_map),
        ),
        ("/v1/maps/{map_id}/coverage", &["get"], get(coverage)),
        ("/v1/maps/{map_id}/image.png", &["get"], get(image)),
        ("/v1/maps/{map_id}/nav2-mask", &["get"], get(nav2_mask)),
        ("/v1/maps/{map_id}/values.npy", &["get"], get(values_npy)),
        ("/v1/jobs", &["get"], get(list_jobs)),
        (
            "/v1/jobs/{job_id}",
            &["get", "delete"],
            get(get_job).merge(delete(cancel_job)),
        ),
        ("/v1/placements", &["post"], post(place)),
        (
            "/v1/placements/{placement_id}",
            &["get"],
            get(get_placement),
        ),
        ("/v1/paths", &["post"], post(plan_path)),
        ("/v1/sweeps", &["post"], post(sweep)),
    ]
}

pub fn router() -> Router<AppState> {
    route_table()
        .into_iter()
        .fold(Router::new(), |r, (path, _, handler)| {
            r.route(path, handler)
        })
}

/// The JSON body extractor of this API: strict parsing, problem+json on every failure, and the
/// configured body limit named in the 413.
pub(crate) struct Body<T>(pub T);

impl<T: serde::de::DeserializeOwned> FromRequest<AppState> for Body<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, ApiError> {
        if let Some(ct) = req.headers().get(header::CONTENT_TYPE) {
            let ct = ct.to_str().unwrap_or("");
            let essence = ct
                .split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase();
            if essence != "application/json" && !essence.ends_with("+json") {
                return Err(ApiError::unsupported_media_type(format!(
                    "expected application/json, got {ct:?}"
                )));
            }
        }
        let limit = state.limits().max_body_bytes;
        let bytes = axum::body::Bytes::from_request(req, state)
            .await
            .map_err(|rejection| {
                if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
                    ApiError::body_too_large(limit as u64)
                } else {
                    ApiError::malformed_json(rejection.body_text())
                }
            })?;
        parse_json(&bytes).map(Body)
    }
}

// ---------------------------------------------------------------- operations endpoints

#[derive(Serialize)]
struct Health {
    status: &'static str,
}

async fn healthz() -> Json<Health> {
    Json(Health { status: "ok" })
}

#[derive(Serialize)]
struct Readiness {
    status: &'static str,
    scenarios: usize,
}

async fn readyz(State(state): State<AppState>) -> Result<Json<Readiness>, ApiError> {
    if !state.is_ready() {
        return Err(ApiError::not_ready());
    }
    Ok(Json(Readiness {
        status: "ready",
        scenarios: state.registry().list().len(),
    }))
}

#[derive(Serialize)]
struct Version {
    name: &'static str,
    version: &'static str,
    sdr_sca_available: bool,
}

async fn version() -> Json<Version> {
    Json(Version {
        name: env!("CARGO_PKG_NAME"),
        version: env!("CARGO_PKG_VERSION"),
        sdr_sca_available: SolverKind::SdrSca.is_available(),
    })
}

async fn metrics_text(State(state): State<AppState>) -> Response {
    state.cache().record_size();
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.render_metrics(),
    )
        .into_response()
}

// ---------------------------------------------------------------- scenarios

#[derive(Serialize)]
struct ScenarioList {
    scenarios: Vec<ScenarioSummary>,
}

async fn list_scenarios(State(state): State<AppState>) -> Json<ScenarioList> {
    Json(ScenarioList {
        scenarios: state.registry().list(),
    })
}

#[derive(Serialize)]
struct ScenarioDocument {
    #[serde(flatten)]
    summary: ScenarioSummary,
    scenario: Scenario,
}

/// A scenario document embedded in a request at `prefix` (e.g. `"map.scenario."`).
fn parse_scenario(value: serde_json::Value, prefix: &str) -> Result<Scenario, ApiError> {
    Scenario::from_value(value).map_err(|e| ApiError::invalid_scenario(e.within(prefix)))
}

async fn register_scenario(
    State(state): State<AppState>,
    Body(value): Body<serde_json::Value>,
) -> Result<Response, ApiError> {
    let scenario = parse_scenario(value, "")?;
    let (stored, created) = state.register_scenario(scenario, "api")?;
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    let summary = stored.summary();
    let location = summary.href.clone();
    let body = ScenarioDocument {
        summary,
        scenario: (*stored.scenario).clone(),
    };
    Ok((status, [(header::LOCATION, location)], Json(body)).into_response())
}

async fn get_scenario(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ScenarioDocument>, ApiError> {
    let stored = state
        .registry()
        .get(&id)
        .ok_or_else(|| ApiError::not_found("scenario", &id))?;
    Ok(Json(ScenarioDocument {
        summary: stored.summary(),
        scenario: (*stored.scenario).clone(),
    }))
}

/// Deletes an API-registered scenario and the cached maps built from it. A scenario that a
/// queued or running job needs is kept (409 with the job).
async fn delete_scenario(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if let Some(job) = state
        .jobs()
        .live()
        .into_iter()
        .find(|j| j.scenario_id == id)
    {
        return Err(ApiError::scenario_in_use(&id, &job.id));
    }
    state.registry().delete(&id)?;
    for (map_id, map) in state.cache().entries() {
        if map.key.scenario_id == id {
            state.cache().remove(&map_id).await;
        }
    }
    tracing::info!(scenario_id = %id, "scenario deleted");
    Ok(StatusCode::NO_CONTENT)
}

// ---------------------------------------------------------------- maps

/// What defines a map: a scenario (registered id or inline document) and the map parameters.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MapRequest {
    #[serde(default, deserialize_with = "present")]
    scenario_id: Option<String>,
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
struct MapSummary {
    map_id: String,
    state: &'static str,
    key: MapKey,
    unit: &'static str,
    stats: MapStats,
    build_seconds: f64,
    href: String,
}

fn summary(map: &RadioMap) -> MapSummary {
    let map_id = map.key.id();
    MapSummary {
        href: format!("/v1/maps/{map_id}"),
        map_id,
        state: "ready",
        key: map.key.clone(),
        unit: map.key.unit(),
        stats: map.stats(),
        build_seconds: map.build_seconds,
    }
}

/// The scenario a request names: a registered one by `scenario_id`, or an inline document
/// (`inline` true: register it once the whole request is valid). Returns its id too.
fn scenario_of(
    state: &AppState,
    scenario_id: Option<String>,
    scenario: Option<serde_json::Map<String, serde_json::Value>>,
    prefix: &str,
) -> Result<(String, Arc<Scenario>, bool), ApiError> {
    match (scenario_id, scenario) {
        (Some(id), None) => {
            // An unknown id is "not found" (404), as an unknown map_id is, naming the field.
            let stored = state.registry().get(&id).ok_or_else(|| {
                ApiError::not_found("scenario", &id).with_field(format!("{prefix}scenario_id"))
            })?;
            Ok((id, stored.scenario.clone(), false))
        }
        (None, Some(doc)) => {
            let scenario = parse_scenario(doc.into(), &format!("{prefix}scenario."))?;
            Ok((scenario.content_hash(), Arc::new(scenario), true))
        }
        _ => Err(ApiError::invalid(
            format!("{prefix}scenario_id"),
            "give exactly one of scenario_id (a registered scenario) and scenario (an inline document)",
        )),
    }
}

/// Resolves a map request to a scenario and a normalised key. An inline scenario is registered
/// only once the whole request has been validated, so a rejected request leaves no trace.
fn resolve(
    state: &AppState,
    request: MapRequest,
    prefix: &str,
) -> Result<(Arc<Scenario>, MapKey), ApiError> {
    let (id, scenario, inline) = scenario_of(state, request.scenario_id, request.scenario, prefix)?;
    let key = MapKey::new(
        &id,
        &scenario,
        request.kind,
        request.phases,
        request.access,
        request.solver,
    )
    .map_err(|e| e.within(prefix))?;
    let cells = scenario.grid().cells();
    let limit = state.limits().max_rate_cells;
    if key.kind == MapKind::Rate && cells > limit {
        return Err(ApiError::limit_exceeded(
            format!("{prefix}kind"),
            limit as u64,
            format!("rate maps are limited to {limit} cells; this grid has {cells}"),
        ));
    }
    if inline {
        let (stored, _) = state.register_scenario((*scenario).clone(), "api")?;
        return Ok((stored.scenario.clone(), key));
    }
    Ok((scenario, key))
}

/// The map, waiting for cheap builds; `Err(Response)` is the 202 job answer for long ones.
async fn obtain(
    state: &AppState,
    scenario: Arc<Scenario>,
    key: MapKey,
) -> Result<Result<Arc<RadioMap>, Response>, ApiError> {
    let cheap = key.kind == MapKind::Gain && scenario.grid().cells() <= state.limits().sync_cells;
    match state.jobs().request(state.cache(), scenario, key).await? {
        MapRequestOutcome::Ready(map) => Ok(Ok(map)),
        MapRequestOutcome::Building(job) if cheap => {
            job.finished().await;
            match state.cache().peek(job.map_id().unwrap_or_default()).await {
                Some(map) => Ok(Ok(map)),
                None => {
                    Err(ApiError::build_failed(job.view().error.unwrap_or_else(
                        || format!("job {} did not finish", job.id),
                    )))
                }
            }
        }
        MapRequestOutcome::Building(job) => Ok(Err(accepted(job.view()))),
    }
}

fn accepted(view: JobView) -> Response {
    let location = view.href.clone();
    (
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(view),
    )
        .into_response()
}

async fn request_map(
    State(state): State<AppState>,
    Body(request): Body<MapRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let (scenario, key) = resolve(&state, request, "")?;
    Ok(match obtain(&state, scenario, key).await? {
        Ok(map) => Json(Timed::since(started, summary(&map))).into_response(),
        Err(job) => job,
    })
}

#[derive(Serialize)]
struct MapList {
    maps: Vec<MapSummary>,
}

async fn list_maps(State(state): State<AppState>) -> Json<MapList> {
    let mut maps: Vec<MapSummary> = state
        .cache()
        .entries()
        .iter()
        .map(|(_, m)| summary(m))
        .collect();
    maps.sort_by(|a, b| a.map_id.cmp(&b.map_id));
    Json(MapList { maps })
}

async fn cached_map(state: &AppState, map_id: &str) -> Result<Arc<RadioMap>, ApiError> {
    if let Some(map) = state.cache().get(map_id).await {
        return Ok(map);
    }
    Err(match state.jobs().building(map_id).await {
        Some(job) => ApiError::map_not_ready(map_id, &job.id),
        None => ApiError::not_found("map", map_id),
    })
}

/// Drops a cached map (the next request for it builds it again). A map being built answers
/// 409 with its job: cancel the job instead.
async fn delete_map(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if let Some(job) = state.jobs().building(&map_id).await {
        return Err(ApiError::map_not_ready(&map_id, &job.id));
    }
    if !state.cache().remove(&map_id).await {
        return Err(ApiError::not_found("map", &map_id));
    }
    tracing::info!(map_id = %map_id, "map deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// A built map and the scenario it was built from.
async fn map_and_scenario(
    state: &AppState,
    map_id: &str,
) -> Result<(Arc<RadioMap>, Arc<Scenario>), ApiError> {
    let map = cached_map(state, map_id).await?;
    let stored = state
        .registry()
        .get(&map.key.scenario_id)
        .ok_or_else(|| ApiError::not_found("scenario", &map.key.scenario_id))?;
    Ok((map, stored.scenario.clone()))
}

async fn get_map(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let map = cached_map(&state, &map_id).await?;
    let cells = map.grid.cells();
    let bytes = off_runtime_if_big(cells, move || {
        serde_json::to_vec(&Timed::since(started, map.body()))
    })
    .await?;
    let bytes = bytes.map_err(|e| ApiError::internal(format!("serialising the map: {e}")))?;
    Ok(([(header::CONTENT_TYPE, "application/json")], bytes).into_response())
}

/// Work on a map with more cells than this (path and sweep searches, map bodies, pictures)
/// runs on tokio's blocking pool. A search or a serialisation touches every cell at a few tens
/// of nanoseconds each, so past ~10 000 cells it would hold an async worker thread for longer
/// than the ~0.1–1 ms tokio budgets between awaits, and every other request on that thread
/// (health checks included) would wait. Below it (the paper's map has 1 681 cells) the work is
/// cheaper than the hand-off to another thread.
const INLINE_WORK_CELLS: usize = 10_000;

/// Runs `work` inline for small maps and on the blocking pool for big ones (see
/// [`INLINE_WORK_CELLS`]).
async fn off_runtime_if_big<T: Send + 'static>(
    cells: usize,
    work: impl FnOnce() -> T + Send + 'static,
) -> Result<T, ApiError> {
    if cells <= INLINE_WORK_CELLS {
        return Ok(work());
    }
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| ApiError::internal(format!("the query's worker failed: {e}")))
}

/// Rejects query parameters outside `allowed`, naming the first unknown one.
fn only_query(query: &HashMap<String, String>, allowed: &[&str]) -> Result<(), ApiError> {
    match query.keys().find(|k| !allowed.contains(&k.as_str())) {
        Some(unknown) => Err(ApiError::invalid(
            unknown.clone(),
            "unknown query parameter",
        )),
        None => Ok(()),
    }
}

#[derive(Serialize)]
struct Coverage {
    map_id: String,
    unit: &'static str,
    threshold: f64,
    /// η(γ), paper eq. 44.
    coverage: f64,
    free_cells: usize,
    covered_cells: usize,
}

async fn coverage(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Coverage>, ApiError> {
    only_query(&query, &["threshold"])?;
    let threshold = query.get("threshold").ok_or_else(|| {
        ApiError::invalid("threshold", "the threshold query parameter is required")
    })?;
    let threshold = parse_finite(threshold).map_err(|e| ApiError::invalid("threshold", e))?;
    let map = cached_map(&state, &map_id).await?;
    let eta = map.coverage(threshold);
    let free = map.free_cells();
    Ok(Json(Coverage {
        map_id,
        unit: map.key.unit(),
        threshold,
        coverage: eta,
        free_cells: free,
        covered_cells: (eta * free as f64).round() as usize,
    }))
}

/// An optional "x,y" query parameter.
fn query_point(
    query: &HashMap<String, String>,
    name: &'static str,
) -> Result<Option<[f64; 2]>, ApiError> {
    query
        .get(name)
        .map(|text| parse_point(text).map_err(|e| ApiError::invalid(name, e)))
        .transpose()
}

/// The map as a PNG; with `start` and `goal`, the path at `threshold` (default "max") drawn on it.
async fn image(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(&query, &["threshold", "start", "goal", "cell_px"])?;
    let threshold = match query.get("threshold") {
        None => Threshold::Max,
        Some(text) => text
            .parse::<Threshold>()
            .map_err(|e| ApiError::invalid("threshold", e))?,
    };
    let path_ends = match (query_point(&query, "start")?, query_point(&query, "goal")?) {
        (Some(s), Some(g)) => Some((s, g)),
        (None, None) => None,
        (start, _) => {
            return Err(ApiError::invalid(
                if start.is_none() { "start" } else { "goal" },
                "give both start and goal, or neither",
            ));
        }
    };
    let cell_px = query
        .get("cell_px")
        .map(|text| {
            text.parse::<usize>()
                .ok()
                .filter(|px| (1..=render::MAX_CELL_PX).contains(px))
                .ok_or_else(|| {
                    ApiError::limit_exceeded(
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
    let (map, scenario) = map_and_scenario(&state, &map_id).await?;
    // Rendering touches every pixel, so it always leaves the async threads.
    let bytes = tokio::task::spawn_blocking(move || -> Result<Option<Vec<u8>>, FieldError> {
        let options = match path_ends {
            Some((s, g)) => {
                RenderOptions::for_path(&map, &planner::plan(&map, s, g, threshold, 1.0)?)
            }
            None => RenderOptions {
                threshold: match threshold {
                    Threshold::Value(t) => Some(t),
                    Threshold::Max => None,
                },
                ..RenderOptions::default()
            },
        };
        let options = RenderOptions { cell_px, ..options };
        Ok(render::png(&map, &scenario, &options))
    })
    .await
    .map_err(|e| ApiError::internal(format!("rendering failed: {e}")))??
    .ok_or_else(|| {
        ApiError::limit_exceeded(
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
async fn nav2_mask(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(&query, &["threshold", "mask", "best"])?;
    let number = |name: &'static str| {
        query
            .get(name)
            .map(|text| parse_finite(text).map_err(|e| ApiError::invalid(name, e)))
            .transpose()
    };
    let threshold = number("threshold")?.ok_or_else(|| {
        ApiError::invalid("threshold", "the threshold query parameter is required")
    })?;
    let best = number("best")?;
    let kind = query
        .get("mask")
        .map(|text| {
            text.parse::<MaskKind>()
                .map_err(|e| ApiError::invalid("mask", e))
        })
        .transpose()?
        .unwrap_or_default();
    let map = cached_map(&state, &map_id).await?;
    let cells = map.grid.cells();
    let archive = off_runtime_if_big(cells, move || {
        export::nav2_mask(&map, kind, threshold, best).map(|mask| mask.tar())
    })
    .await?
    .map_err(|e| ApiError::invalid(e.field, e.reason))?;
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

/// The map's values as a NumPy `.npy` (float32, shape (nx, ny), NaN where occupied).
async fn values_npy(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(&query, &[])?;
    let map = cached_map(&state, &map_id).await?;
    let cells = map.grid.cells();
    let bytes = off_runtime_if_big(cells, move || export::npy(&map)).await?;
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

// ---------------------------------------------------------------- placements

/// A placement search: the scenario (by id or inline) and the search (docs/model.md §7).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PlacementRequest {
    #[serde(default, deserialize_with = "present")]
    scenario_id: Option<String>,
    #[serde(default, deserialize_with = "present")]
    scenario: Option<serde_json::Map<String, serde_json::Value>>,
    #[serde(default)]
    what: What,
    #[serde(default)]
    index: usize,
    candidates: Candidates,
    objective: Objective,
    #[serde(default, deserialize_with = "present")]
    phases: Option<PhaseMode>,
    /// How many of the best candidates to register, with their maps built, so their map ids
    /// answer path queries at once.
    #[serde(default, deserialize_with = "present")]
    keep: Option<usize>,
}

/// Candidates registered and built by default, and at most.
const DEFAULT_KEEP: usize = 3;
const MAX_KEEP: usize = 20;

/// Searches small enough (candidates × cells × APs) are answered while the request waits, as
/// gain maps of up to `sync_cells` cells are; a candidate's cell costs about what a gain-map
/// cell does, and four maps' worth is still well under a second.
const SYNC_PLACEMENT_MAPS: usize = 4;

/// A placement answer as the API returns it: the search's answer (the CLI's body), the job it
/// ran as and how many of the best candidates are registered with their maps cached.
#[derive(Serialize)]
struct PlacementBody<'a> {
    placement_id: &'a str,
    #[serde(flatten)]
    answer: &'a PlacementAnswer,
    registered: usize,
    href: String,
}

fn placement_body<'a>(job: &'a Job, outcome: &'a PlacementOutcome) -> PlacementBody<'a> {
    PlacementBody {
        placement_id: &job.id,
        answer: &outcome.answer,
        registered: outcome.registered,
        href: format!("/v1/placements/{}", job.id),
    }
}

async fn place(
    State(state): State<AppState>,
    Body(request): Body<PlacementRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let keep = request.keep.unwrap_or(DEFAULT_KEEP);
    if keep > MAX_KEEP {
        return Err(ApiError::limit_exceeded(
            "keep",
            MAX_KEEP as u64,
            format!("at most {MAX_KEEP} candidates are registered"),
        ));
    }
    let (_, scenario, inline) = scenario_of(&state, request.scenario_id, request.scenario, "")?;
    let search = Search {
        what: request.what,
        index: request.index,
        candidates: request.candidates,
        objective: request.objective,
        phases: request.phases,
    };
    // Every check (the candidates, the limits, the objective's points) before any work.
    let (checked_scenario, checked_search) = (scenario.clone(), search.clone());
    let candidates = tokio::task::spawn_blocking(move || {
        placement::candidates(&checked_scenario, &checked_search)
    })
    .await
    .map_err(|e| ApiError::internal(format!("checking the candidates failed: {e}")))??;
    if inline {
        state.register_scenario((*scenario).clone(), "api")?;
    }
    let work = candidates.len() * scenario.grid().cells() * scenario.access_points().len();
    let registrar = state.clone();
    let job = state.jobs().place(
        state.cache(),
        scenario,
        search,
        candidates,
        keep,
        move |s| {
            registrar
                .register_scenario(s, "api")
                .inspect_err(|e| {
                    tracing::warn!(error = %e.problem.detail, "a placement candidate was not registered")
                })
                .is_ok()
        },
    )?;
    if work > SYNC_PLACEMENT_MAPS * state.limits().sync_cells {
        return Ok(accepted(job.view()));
    }
    job.finished().await;
    let outcome = job.placement().ok_or_else(|| {
        ApiError::build_failed(
            job.view()
                .error
                .unwrap_or_else(|| format!("job {} did not finish", job.id)),
        )
    })?;
    Ok(Json(Timed::since(started, placement_body(&job, &outcome))).into_response())
}

async fn get_placement(
    State(state): State<AppState>,
    Path(placement_id): Path<String>,
) -> Result<Response, ApiError> {
    let job = state
        .jobs()
        .get(&placement_id)
        .filter(|j| matches!(j.work, Work::Placement { .. }))
        .ok_or_else(|| ApiError::not_found("placement", &placement_id))?;
    match job.placement() {
        Some(outcome) => Ok(Json(placement_body(&job, &outcome)).into_response()),
        None if job.state().is_terminal() => {
            Err(ApiError::job_finished(&job.id, job.view().state.label()))
        }
        None => Err(ApiError::placement_not_ready(&job.id)),
    }
}

// ---------------------------------------------------------------- jobs

#[derive(Serialize)]
struct JobList {
    jobs: Vec<JobView>,
}

async fn list_jobs(State(state): State<AppState>) -> Json<JobList> {
    Json(JobList {
        jobs: state.jobs().list(),
    })
}

async fn get_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<JobView>, ApiError> {
    let job = state
        .jobs()
        .get(&id)
        .ok_or_else(|| ApiError::not_found("job", &id))?;
    Ok(Json(job.view()))
}

async fn cancel_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<(StatusCode, Json<JobView>), ApiError> {
    let job = state.jobs().cancel(&id)?;
    Ok((StatusCode::ACCEPTED, Json(job.view())))
}

// ---------------------------------------------------------------- paths and sweeps

/// 2^53 − 1: integers above it lose precision in JavaScript and other double-based JSON clients.
const MAX_JSON_SAFE_INTEGER: u64 = (1 << 53) - 1;

/// A path query names its map by `map_id` (a built map) or `map` (the request defining it).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PathRequest {
    #[serde(default, deserialize_with = "present")]
    map_id: Option<String>,
    #[serde(default, deserialize_with = "present")]
    map: Option<MapRequest>,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    /// Monte Carlo draws per waypoint for the Jensen-gap check (paper Fig. 10).
    #[serde(default, deserialize_with = "present")]
    monte_carlo_draws: Option<usize>,
    #[serde(default, deserialize_with = "present")]
    seed: Option<u64>,
}

/// The map a path or sweep query names, or the 202 answer while it is built.
async fn map_for_query(
    state: &AppState,
    map_id: Option<String>,
    map: Option<MapRequest>,
) -> Result<Result<(Arc<RadioMap>, Arc<Scenario>), Response>, ApiError> {
    match (map_id, map) {
        (Some(id), None) => Ok(Ok(map_and_scenario(state, &id).await?)),
        (None, Some(request)) => {
            let (scenario, key) = resolve(state, request, "map.")?;
            Ok(obtain(state, scenario.clone(), key)
                .await?
                .map(|m| (m, scenario)))
        }
        _ => Err(ApiError::invalid(
            "map_id",
            "give exactly one of map_id and map",
        )),
    }
}

fn check_point(field: &'static str, p: [f64; 2]) -> Result<[f64; 2], ApiError> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(p)
    } else {
        Err(ApiError::invalid(field, "coordinates must be finite"))
    }
}

async fn plan_path(
    State(state): State<AppState>,
    Body(request): Body<PathRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let start = check_point("start", request.start)?;
    let goal = check_point("goal", request.goal)?;
    let limit = state.limits().max_draws;
    if let Some(draws) = request.monte_carlo_draws
        && (draws == 0 || draws > limit)
    {
        return Err(ApiError::limit_exceeded(
            "monte_carlo_draws",
            limit as u64,
            format!("must lie in 1..={limit}"),
        ));
    }
    if request
        .seed
        .is_some_and(|seed| seed > MAX_JSON_SAFE_INTEGER)
    {
        return Err(ApiError::limit_exceeded(
            "seed",
            MAX_JSON_SAFE_INTEGER,
            "must be at most 2^53 − 1, the largest integer every JSON client keeps exact",
        ));
    }
    let (map, scenario) = match map_for_query(&state, request.map_id, request.map).await? {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let cells = map.grid.cells();
    let (threshold, v_max) = (request.threshold, scenario.mru.v_max_mps);
    let planned = map.clone();
    let path = off_runtime_if_big(cells, move || {
        planner::plan(&planned, start, goal, threshold, v_max)
    })
    .await??;
    let monte_carlo = match request.monte_carlo_draws {
        Some(draws) if path.feasible => {
            let (scenario, map, path) = (scenario.clone(), map.clone(), path.clone());
            let seed = request.seed.unwrap_or(1);
            // Thousands of draws per waypoint: always off the async threads.
            let report = tokio::task::spawn_blocking(move || {
                montecarlo::check_path(&scenario, &map, &path, draws, seed)
            })
            .await
            .map_err(|e| ApiError::internal(format!("the Monte Carlo check failed: {e}")))?;
            Some(report)
        }
        _ => None,
    };
    let answer = Timed::since(started, CheckedPath { path, monte_carlo });
    Ok(Json(answer).into_response())
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SweepRequest {
    #[serde(default, deserialize_with = "present")]
    map_id: Option<String>,
    #[serde(default, deserialize_with = "present")]
    map: Option<MapRequest>,
    start: [f64; 2],
    goal: [f64; 2],
    thresholds: Vec<f64>,
}

async fn sweep(
    State(state): State<AppState>,
    Body(request): Body<SweepRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let start = check_point("start", request.start)?;
    let goal = check_point("goal", request.goal)?;
    let limit = state.limits().max_sweep;
    if request.thresholds.is_empty() || request.thresholds.len() > limit {
        return Err(ApiError::limit_exceeded(
            "thresholds",
            limit as u64,
            format!("give 1 to {limit} thresholds"),
        ));
    }
    if let Some(k) = request.thresholds.iter().position(|t| !t.is_finite()) {
        return Err(ApiError::invalid(
            format!("thresholds[{k}]"),
            "must be a finite number",
        ));
    }
    let (map, scenario) = match map_for_query(&state, request.map_id, request.map).await? {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let (cells, v_max, thresholds) = (map.grid.cells(), scenario.mru.v_max_mps, request.thresholds);
    let answer: SweepAnswer = off_runtime_if_big(cells, move || {
        planner::sweep(&map, start, goal, &thresholds, v_max)
    })
    .await??;
    Ok(Json(Timed::since(started, answer)).into_response())
}
