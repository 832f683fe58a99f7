//! HTTP handlers and the route table (the contract is `openapi.yaml`). Handlers translate
//! between JSON and the engine; all physics lives in the library modules.

use super::AppState;
use super::answers::{OpenAnswer, PathQuery};
use super::auth::Caller;
use super::cache::ScenarioSummary;
use super::cluster::Cluster;
use super::errors::{ApiError, parse_json};
use super::jobs::{
    Job, JobRecord, JobState, JobView, MapRequestOutcome, PlacementOutcome, PlacementSearch, Work,
};
use super::json::serialize_sized;
use axum::extract::{FromRequest, Path, Query, Request, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, delete, get, post};
use axum::{Json, Router};
use irs_answers::export::{self, MaskKind};
use irs_answers::path::{self, CheckedPath};
use irs_answers::phase_text::{PhaseFormat, PhasePrecision};
use irs_answers::render::{self, RenderOptions};
use irs_answers::scenario::ScenarioDocument as _;
use irs_answers::timing::Timed;
use irs_model::input::{FieldError, parse_finite, parse_point, present};
use irs_model::montecarlo;
use irs_model::phases::PhaseMode;
use irs_model::placement::{self, Candidates, Objective, Search, What};
use irs_model::planner::{self, SweepAnswer, Threshold};
use irs_model::radiomap::cost;
use irs_model::radiomap::{MapKey, MapKind, MapStats, Progress, RadioMap, WorkError};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;
use irs_model::solver::SolverKind;
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
        let Some(ct) = req.headers().get(header::CONTENT_TYPE) else {
            return Err(ApiError::unsupported_media_type(
                "the body must be JSON: send Content-Type: application/json",
            ));
        };
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
        let limit = state.limits().max_body_bytes;
        let timeout = state.limits().body_timeout;
        let read = axum::body::Bytes::from_request(req, state);
        let bytes = tokio::time::timeout(timeout, read)
            .await
            .map_err(|_| ApiError::body_timeout(timeout.as_secs()))?
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

/// Items per page of a listing when the client does not say, and at most.
const DEFAULT_PAGE: usize = 100;
const MAX_PAGE: usize = 1000;

/// A listing's `limit` and `cursor` query parameters (the cursor is the `next_cursor` of the
/// page before: the key of its last item).
struct Page {
    limit: usize,
    cursor: Option<String>,
}

impl Page {
    fn of(query: &HashMap<String, String>) -> Result<Page, ApiError> {
        only_query(query, &["limit", "cursor"])?;
        let limit = match query.get("limit") {
            None => DEFAULT_PAGE,
            Some(text) => text
                .parse::<usize>()
                .ok()
                .filter(|n| (1..=MAX_PAGE).contains(n))
                .ok_or_else(|| {
                    ApiError::limit_exceeded(
                        "limit",
                        MAX_PAGE as u64,
                        format!("must be a whole number from 1 to {MAX_PAGE}"),
                    )
                })?,
        };
        let cursor = query.get("cursor").cloned();
        if let Some(c) = &cursor
            && (c.is_empty() || c.len() > 128 || !c.bytes().all(|b| b.is_ascii_alphanumeric()))
        {
            return Err(ApiError::invalid(
                "cursor",
                "not a cursor this server gave: use a listing's next_cursor",
            ));
        }
        Ok(Page { limit, cursor })
    }

    /// The page of `items` (in listing order, each with its key) after the cursor, and the
    /// cursor of the next page if there is one. `after(key, cursor)` tells whether an item
    /// comes after the cursor in listing order.
    fn cut<T>(
        &self,
        items: Vec<(String, T)>,
        after: impl Fn(&str, &str) -> bool,
    ) -> (Vec<T>, Option<String>) {
        let mut rest = items
            .into_iter()
            .filter(|(key, _)| self.cursor.as_deref().is_none_or(|c| after(key, c)));
        let page: Vec<(String, T)> = rest.by_ref().take(self.limit).collect();
        let next = match rest.next() {
            Some(_) => page.last().map(|(key, _)| key.clone()),
            None => None,
        };
        (page.into_iter().map(|(_, item)| item).collect(), next)
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
    if let Some(reason) = state.cluster().and_then(|c| c.unavailable()) {
        return Err(ApiError::store_unavailable(reason));
    }
    Ok(Json(Readiness {
        status: "ready",
        scenarios: state.registry().len(),
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
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The scenarios the caller may see (the server's own and, with authentication on, the
/// caller's), by id, a page at a time.
async fn list_scenarios(
    State(state): State<AppState>,
    caller: Caller,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<ScenarioList>, ApiError> {
    let page = Page::of(&query)?;
    let listed = state.registry().list(&caller);
    let keyed = listed.into_iter().map(|s| (s.id.clone(), s)).collect();
    let (scenarios, next_cursor) = page.cut(keyed, |key, cursor| key > cursor);
    Ok(Json(ScenarioList {
        scenarios,
        next_cursor,
    }))
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
    caller: Caller,
    Body(value): Body<serde_json::Value>,
) -> Result<Response, ApiError> {
    let scenario = parse_scenario(value, "")?;
    let (stored, created) = state.register_scenario(scenario, "api", &caller)?;
    state.share_scenario(&stored, true).await?;
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
        .shared_scenario(&id)
        .await?
        .ok_or_else(|| ApiError::not_found("scenario", &id))?;
    Ok(Json(ScenarioDocument {
        summary: stored.summary(),
        scenario: (*stored.scenario).clone(),
    }))
}

/// Deletes the caller's registration of an API scenario; with the last registration the
/// scenario goes, and the cached maps built from it. A scenario that a queued or running job
/// needs is kept (409 with the job).
async fn delete_scenario(
    State(state): State<AppState>,
    caller: Caller,
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
    if state.registry().delete(&id, &caller)? {
        state.cache().remove_scenario_maps(&id).await;
        if let Some(cluster) = state.cluster() {
            cluster.delete_scenario(&id).await?;
        }
        tracing::info!(scenario_id = %id, "scenario deleted");
    }
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
    let map_id = map.id.clone();
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

/// In a cluster: brings a scenario registered on another replica here, so the synchronous
/// [`scenario_of`] finds it (nothing to do for an inline scenario or a local one).
async fn fetch_scenario(state: &AppState, scenario_id: Option<&str>) -> Result<(), ApiError> {
    if let Some(id) = scenario_id
        && state.cluster().is_some()
    {
        state.shared_scenario(id).await?;
    }
    Ok(())
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

/// Resolves a map request to a scenario and a normalised key, and checks the build's estimated
/// cost against the budget. An inline scenario is registered (for `caller`) only once the whole
/// request has been validated, so a rejected request leaves no trace.
fn resolve(
    state: &AppState,
    caller: &Caller,
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
    check_budget(
        &format!("{prefix}kind"),
        "map build",
        cost::build_seconds(&scenario, &key),
        state.limits().max_build_cpu_s,
    )?;
    // A map the cache could never hold would be built, handed out once and dropped: refuse it.
    let (bytes, budget) = (cost::map_bytes(&scenario, &key), state.limits().cache_bytes);
    if bytes > budget as f64 {
        return Err(ApiError::limit_exceeded(
            format!("{prefix}kind"),
            budget,
            format!(
                "this map would take about {:.0} MiB, more than the map cache's whole budget of \
                 {} MiB (--cache-mb): use a coarser grid or fewer elements",
                bytes / 1048576.0,
                budget / 1048576
            ),
        ));
    }
    if inline {
        let (stored, _) = state.register_scenario((*scenario).clone(), "api", caller)?;
        return Ok((stored.scenario.clone(), key));
    }
    Ok((scenario, key))
}

/// Refuses work whose estimated CPU time exceeds the budget (422 naming `field` and the limit
/// in seconds), before any of it is done.
fn check_budget(field: &str, what: &str, seconds: f64, budget: f64) -> Result<(), ApiError> {
    if seconds <= budget {
        return Ok(());
    }
    Err(ApiError::limit_exceeded(
        field,
        budget.ceil() as u64,
        format!(
            "this {what} would take about {seconds:.0} s of CPU, above the server's budget of \
             {budget:.0} s: use a coarser grid, fewer elements (coherent grouping) or fewer \
             candidates or draws"
        ),
    ))
}

/// The map, waiting for cheap builds; `Err(Response)` is the 202 job answer for long ones.
async fn obtain(
    state: &AppState,
    caller: &Caller,
    scenario: Arc<Scenario>,
    key: MapKey,
) -> Result<Result<Arc<RadioMap>, Response>, ApiError> {
    let cheap = key.kind == MapKind::Gain && scenario.grid().cells() <= state.limits().sync_cells;
    if let Some(cluster) = state.cluster() {
        return obtain_shared(state, cluster, caller, key, cheap).await;
    }
    let outcome = state
        .jobs()
        .request(state.cache(), scenario, key, caller.owner())
        .await?;
    match outcome {
        MapRequestOutcome::Ready(map) => Ok(Ok(map)),
        MapRequestOutcome::Building(job) if cheap => {
            // The job hands its map over itself, whatever the cache has done with it since.
            match job.wait_for_map().await {
                Some(map) => Ok(Ok(map)),
                None => Err(ApiError::build_failed(job.view().error.unwrap_or_else(
                    || format!("job {} ended {} without a map", job.id, job.state().label()),
                ))),
            }
        }
        MapRequestOutcome::Building(job) => Ok(Err(accepted(job.view()))),
    }
}

/// [`obtain`] in a cluster: the map from any replica's build. The build is queued in the
/// shared stream (once for the whole cluster) and runs on whichever replica has a free worker;
/// a cheap one is waited for by polling its record.
async fn obtain_shared(
    state: &AppState,
    cluster: &Cluster,
    caller: &Caller,
    key: MapKey,
    cheap: bool,
) -> Result<Result<Arc<RadioMap>, Response>, ApiError> {
    let map_id = irs_answers::map::map_id(&key);
    if let Some(map) = state.shared_map(&map_id).await? {
        return Ok(Ok(map));
    }
    // The replica that builds it reads the scenario from the shared store.
    let stored = state
        .shared_scenario(&key.scenario_id)
        .await?
        .ok_or_else(|| ApiError::not_found("scenario", &key.scenario_id))?;
    state.share_scenario(&stored, false).await?;
    let queued = JobRecord::queued(&key, caller.owner().as_ref());
    let (job_id, _) = cluster
        .enqueue(&map_id, &key, queued, state.limits().cluster_queue)
        .await?;
    let record = |r: Option<JobRecord>| {
        r.unwrap_or_else(|| {
            let mut r = JobRecord::queued(&key, None);
            r.job_id = job_id.clone();
            r
        })
    };
    if !cheap {
        return Ok(Err(accepted(record(cluster.job(&job_id).await?).view())));
    }
    loop {
        let current = record(cluster.job(&job_id).await?);
        match current.state {
            JobState::Done => {
                return match state.shared_map(&map_id).await? {
                    Some(map) => Ok(Ok(map)),
                    None => Err(ApiError::build_failed(format!(
                        "job {job_id} is done but its map is in no store"
                    ))),
                };
            }
            s if s.is_terminal() => {
                return Err(ApiError::build_failed(current.error.unwrap_or_else(|| {
                    format!("job {job_id} ended {} without a map", s.label())
                })));
            }
            _ => tokio::time::sleep(SHARED_POLL).await,
        }
    }
}

/// How often a request waiting for another replica's build reads its record: a gain map of
/// the sizes built inline takes tens of milliseconds, so the wait adds at most this.
const SHARED_POLL: std::time::Duration = std::time::Duration::from_millis(20);

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
    caller: Caller,
    Body(request): Body<MapRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    fetch_scenario(&state, request.scenario_id.as_deref()).await?;
    let (scenario, key) = resolve(&state, &caller, request, "")?;
    Ok(match obtain(&state, &caller, scenario, key).await? {
        Ok(map) => Json(Timed::since(started, summary(&map))).into_response(),
        Err(job) => job,
    })
}

#[derive(Serialize)]
struct MapList {
    maps: Vec<MapSummary>,
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The cached maps, by id, a page at a time.
async fn list_maps(
    State(state): State<AppState>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<MapList>, ApiError> {
    let page = Page::of(&query)?;
    let mut entries = state.cache().entries();
    entries.sort_by(|a, b| a.0.cmp(&b.0));
    let (maps, next_cursor) = page.cut(entries, |key, cursor| key > cursor);
    Ok(Json(MapList {
        maps: maps.iter().map(|m| summary(m)).collect(),
        next_cursor,
    }))
}

async fn cached_map(state: &AppState, map_id: &str) -> Result<Arc<RadioMap>, ApiError> {
    if let Some(map) = state.shared_map(map_id).await? {
        return Ok(map);
    }
    if let Some(job) = state.jobs().building(map_id).await {
        return Err(ApiError::map_not_ready(map_id, &job.id));
    }
    if let Some(cluster) = state.cluster()
        && let Some(job_id) = cluster.building(map_id).await?
    {
        return Err(ApiError::map_not_ready(map_id, &job_id));
    }
    Err(ApiError::not_found("map", map_id))
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
    let mut removed = state.cache().remove(&map_id).await;
    if let Some(cluster) = state.cluster() {
        removed |= cluster.delete_map(&map_id).await?;
    }
    if !removed {
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
        .shared_scenario(&map.key.scenario_id)
        .await?
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
    let bytes = heavy(&state, "map body", cells, move |_| {
        serde_json::to_vec(&Timed::since(started, irs_answers::map::body(&map)))
    })
    .await?;
    let bytes = bytes.map_err(|e| ApiError::internal(format!("serialising the map: {e}")))?;
    Ok(([(header::CONTENT_TYPE, "application/json")], bytes).into_response())
}

/// Work on a map with more cells than this (path and sweep searches, map bodies, exports) is a
/// heavy query, run on the query pool under its admission control (`super::queries`). A
/// search or a serialisation touches every cell at a few tens of nanoseconds each, so past
/// ~10 000 cells it would hold an async worker thread for longer than the ~0.1–1 ms tokio
/// budgets between awaits, and every other request on that thread (health checks included)
/// would wait. Below it (the paper's map has 1 681 cells) the work is cheaper than the
/// hand-off to another thread.
const INLINE_WORK_CELLS: usize = 10_000;

/// Runs `work` inline for small maps and as a heavy query for big ones (see
/// [`INLINE_WORK_CELLS`]); the work's [`Progress`] is cancelled if the client goes.
async fn heavy<T: Send + 'static>(
    state: &AppState,
    what: &'static str,
    cells: usize,
    work: impl FnOnce(&Progress) -> T + Send + 'static,
) -> Result<T, ApiError> {
    if cells <= INLINE_WORK_CELLS {
        return Ok(work(&Progress::default()));
    }
    state.queries().run(what, work).await
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
    // Rendering touches every pixel (up to 4096² of them), so it is always a heavy query.
    let render = move |_: &Progress| -> Result<Option<Vec<u8>>, FieldError> {
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
    };
    let bytes = state
        .queries()
        .run("picture", render)
        .await??
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
    let archive = heavy(&state, "mask export", cells, move |_| {
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
    let bytes = heavy(&state, "values export", cells, move |_| export::npy(&map)).await?;
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
    answer: &'a serde_json::Value,
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
    caller: Caller,
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
    fetch_scenario(&state, request.scenario_id.as_deref()).await?;
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
    let candidates = state
        .queries()
        .run("placement check", move |_| {
            placement::candidates(&checked_scenario, &checked_search)
        })
        .await??;
    let cell_evaluations = candidates.len() as f64 * scenario.grid().cells() as f64;
    let mode = search.phases.unwrap_or(PhaseMode::Continuous);
    check_budget(
        "candidates",
        "placement search",
        cost::gain_seconds(&scenario, cell_evaluations, mode),
        state.limits().max_build_cpu_s,
    )?;
    if inline {
        state.register_scenario((*scenario).clone(), "api", &caller)?;
    }
    let work = candidates.len() * scenario.grid().cells() * scenario.access_points().len();
    let (registrar, owner) = (state.clone(), caller.clone());
    let checked = PlacementSearch {
        scenario,
        search,
        candidates,
        keep,
    };
    let job = state.jobs().place(
        state.cache(),
        checked,
        caller.owner(),
        move |s| {
            registrar
                .register_scenario(s, "api", &owner)
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
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The caller's jobs (all jobs with authentication off), newest first, a page at a time.
async fn list_jobs(
    State(state): State<AppState>,
    caller: Caller,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<JobList>, ApiError> {
    let page = Page::of(&query)?;
    let keyed = state
        .jobs()
        .list(&caller)
        .into_iter()
        .map(|(seq, view)| (seq.to_string(), view))
        .collect();
    // Newest first: a job comes after the cursor when it is older (a smaller sequence).
    let older = |key: &str, cursor: &str| match (key.parse::<u64>(), cursor.parse::<u64>()) {
        (Ok(k), Ok(c)) => k < c,
        _ => false,
    };
    let (jobs, next_cursor) = page.cut(keyed, older);
    Ok(Json(JobList { jobs, next_cursor }))
}

async fn get_job(
    State(state): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<JobView>, ApiError> {
    if let Some(job) = state.jobs().get(&id) {
        return Ok(Json(job.view()));
    }
    // Another replica's job, as its builder last recorded it.
    if let Some(cluster) = state.cluster()
        && let Some(record) = cluster.job(&id).await?
    {
        return Ok(Json(record.view()));
    }
    Err(ApiError::not_found("job", &id))
}

async fn cancel_job(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<(StatusCode, Json<JobView>), ApiError> {
    let local = state.jobs().get(&id).is_some();
    if let Some(cluster) = state.cluster().filter(|_| !local) {
        // Another replica runs it: it reads the request at its next heartbeat.
        let record = cluster
            .job(&id)
            .await?
            .filter(|r| caller.may_touch(r.owner().as_ref()))
            .ok_or_else(|| ApiError::not_found("job", &id))?;
        if record.state.is_terminal() {
            return Err(ApiError::job_finished(&id, record.state.label()));
        }
        cluster.request_cancel(&id).await?;
        return Ok((StatusCode::ACCEPTED, Json(record.view())));
    }
    let job = state.jobs().cancel(&id, &caller)?;
    if let Some(cluster) = state.cluster() {
        // Also through the store, for a build whose local job is only a mirror; the local
        // cancellation has happened either way, so a store that is down changes nothing.
        let _ = cluster.request_cancel(&id).await;
    }
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
    /// How finely the waypoints' phases are written in radians (default 1e-4 rad).
    #[serde(default, deserialize_with = "present")]
    phase_precision: Option<PhasePrecision>,
    /// Radians (default) or 16-bit codes in base64.
    #[serde(default, deserialize_with = "present")]
    phase_format: Option<PhaseFormat>,
}

/// The map a path or sweep query names, or the 202 answer while it is built.
async fn map_for_query(
    state: &AppState,
    caller: &Caller,
    map_id: Option<String>,
    map: Option<MapRequest>,
) -> Result<Result<(Arc<RadioMap>, Arc<Scenario>), Response>, ApiError> {
    match (map_id, map) {
        (Some(id), None) => Ok(Ok(map_and_scenario(state, &id).await?)),
        (None, Some(request)) => {
            fetch_scenario(state, request.scenario_id.as_deref()).await?;
            let (scenario, key) = resolve(state, caller, request, "map.")?;
            Ok(obtain(state, caller, scenario.clone(), key)
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
    caller: Caller,
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
    let (format, precision) = path::phase_options(request.phase_format, request.phase_precision)?;
    let found = map_for_query(&state, &caller, request.map_id, request.map).await?;
    let (map, scenario) = match found {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let map_id = map.id.clone();
    // A plain query asked before is answered from the answer cache (service::answers).
    let query = request.monte_carlo_draws.is_none().then(|| {
        PathQuery::new(
            map_id.clone(),
            start,
            goal,
            request.threshold,
            format,
            precision,
        )
    });
    if let Some(kept) = query.as_ref().and_then(|q| state.answers().get(q)) {
        return Ok(kept.respond(started));
    }
    let cells = map.grid.cells();
    let (threshold, v_max) = (request.threshold, scenario.mru.v_max_mps);
    let (planned, cache) = (map.clone(), state.cache().clone());
    let path = heavy(&state, "path", cells, move |_| {
        let index = cache.bottlenecks(&map_id, &planned);
        planner::plan_indexed(&planned, &index, start, goal, threshold, v_max)
    })
    .await??;
    // Written before the Monte Carlo check, which then evaluates the phases as sent.
    let path = path::write_phases(path, format, precision);
    let monte_carlo = match request.monte_carlo_draws {
        Some(draws) if path.feasible => {
            let rate = map.key.kind == MapKind::Rate;
            check_budget(
                "monte_carlo_draws",
                "Monte Carlo check",
                montecarlo::check_seconds(&scenario, path.waypoints.len(), draws, rate),
                state.limits().max_check_cpu_s,
            )?;
            let (scenario, map, path) = (scenario.clone(), map.clone(), path.clone());
            let seed = request.seed.unwrap_or(1);
            // Thousands of draws per waypoint: always a heavy query, cancelled with its client.
            let report = state
                .queries()
                .run("Monte Carlo check", move |progress| {
                    path::check(&scenario, &map, &path, draws, seed, progress)
                })
                .await?
                .map_err(|e| ApiError::internal(e.to_string()))?;
            Some(report)
        }
        _ => None,
    };
    // Sized up front: the phases' text and ~150 bytes per waypoint's other fields, so the
    // buffer is not regrown (and copied) a dozen times on the way to 20–400 kB.
    let capacity = 512
        + path
            .waypoints
            .iter()
            .map(|w| 150 + w.config.phases.json_len_hint())
            .sum::<usize>();
    let answer = OpenAnswer::new(serialize_sized(
        &CheckedPath { path, monte_carlo },
        capacity,
    )?)?;
    if let Some(query) = query {
        state.answers().insert(query, answer.clone());
    }
    Ok(answer.respond(started))
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
    caller: Caller,
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
    let found = map_for_query(&state, &caller, request.map_id, request.map).await?;
    let (map, scenario) = match found {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let (cells, v_max, thresholds) = (map.grid.cells(), scenario.mru.v_max_mps, request.thresholds);
    // A sweep is one search per threshold: heavy once thresholds × cells is, not cells alone.
    let work = cells.saturating_mul(thresholds.len());
    let cache = state.cache().clone();
    let answer: SweepAnswer = heavy(&state, "sweep", work, move |progress| {
        let index = cache.bottlenecks(&map.id, &map);
        planner::sweep(&map, &index, start, goal, &thresholds, v_max, progress)
    })
    .await?
    .map_err(|e| match e {
        WorkError::Invalid(e) => ApiError::from(e),
        WorkError::Cancelled(c) => ApiError::internal(c.to_string()),
    })?;
    Ok(Json(Timed::since(started, answer)).into_response())
}
