//! `/v1/paths`, `/v1/sweeps` and `/v1/maps/{map_id}/coverage`: the queries on a built map
//! (a path at a threshold, a sweep of thresholds, the covered share of the floor).

use super::json;
use super::maps::MapRequest;
use super::problem::ApiError;
use super::{Body, accepted, heavy, only_query};
use crate::app::App;
use crate::app::Error;
use crate::app::answers::{OpenAnswer, PathQuery};
use crate::app::identity::Caller;
use crate::app::jobs::{AnswerKind, SYNC_CHECK_S};
use crate::app::maps::{Obtained, check_budget};
use crate::ids::{JobId, MapId, ScenarioId};
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use irs_answers::path::{self, CheckedPath, FrameId};
use irs_answers::phase_text::{PhaseFormat, PhasePrecision};
use irs_answers::route::{self, RouteFormat};
use irs_answers::timing::{self, Timed};
use irs_answers::vda5050::{self, Header, OrderParams};
use irs_model::input::{FieldError, parse_finite, present};
use irs_model::montecarlo;
use irs_model::planner::{self, PathShape, SweepAnswer, Threshold};
use irs_model::radiomap::{MapKind, RadioMap, Unit, WorkError, body};
use irs_model::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;
use std::time::SystemTime;

#[derive(Serialize)]
pub(super) struct Coverage {
    map_id: MapId,
    unit: &'static str,
    threshold: f64,
    /// η(γ), paper eq. 44.
    coverage: f64,
    free_cells: usize,
    covered_cells: usize,
}

pub(super) async fn coverage(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<Coverage>, ApiError> {
    only_query(&query, &["threshold", "unit"])?;
    let threshold = query
        .get("threshold")
        .ok_or_else(|| Error::invalid("threshold", "the threshold query parameter is required"))?;
    let threshold = parse_finite(threshold).map_err(|e| Error::invalid("threshold", e))?;
    let unit = query
        .get("unit")
        .map(|text| text.parse::<Unit>().map_err(|e| Error::invalid("unit", e)))
        .transpose()?;
    let map = state.map(&caller, &map_id).await?;
    let unit = unit.unwrap_or(map.native_unit());
    let free = map.free_cells();
    let eta = if unit == map.native_unit() {
        map.coverage(threshold)
    } else {
        // Converting a million cells is work for the query pool; the converted values are kept
        // with the map's index in that unit for the next query.
        let (cache, id, cells) = (state.cache().clone(), map_id.clone(), map.grid.cells());
        heavy(&state, "coverage", cells, move |_| {
            let index = cache.unit_index(&id, &map, unit)?;
            Ok::<_, FieldError>(body::coverage(index.values(&map), &map.occupied, threshold))
        })
        .await??
    };
    Ok(Json(Coverage {
        map_id,
        unit: unit.symbol(),
        threshold,
        coverage: eta,
        free_cells: free,
        covered_cells: (eta * free as f64).round() as usize,
    }))
}

/// 2^53 − 1: integers above it lose precision in JavaScript and other double-based JSON clients.
pub(super) const MAX_JSON_SAFE_INTEGER: u64 = (1 << 53) - 1;

/// A path query names its map by `map_id` (a built map) or `map` (the request defining it).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct PathRequest {
    #[serde(default, deserialize_with = "present")]
    map_id: Option<MapId>,
    #[serde(default, deserialize_with = "present")]
    map: Option<MapRequest>,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    /// The unit of the threshold and of the values answered (default: the map's own).
    #[serde(default, deserialize_with = "present")]
    unit: Option<Unit>,
    /// `grid` (8-connected, the default) or `any_angle`.
    #[serde(default, deserialize_with = "present")]
    path_shape: Option<PathShape>,
    /// How far an end in an obstacle or below the threshold may move to a feasible cell (m).
    #[serde(default, deserialize_with = "present")]
    tolerance_m: Option<f64>,
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
    /// The frame the answer names for its positions (default `map`).
    #[serde(default, deserialize_with = "present")]
    frame_id: Option<FrameId>,
    /// The VDA 5050 order's own fields (with `Accept: application/vnd.vda5050.order+json`).
    #[serde(default, deserialize_with = "present")]
    order: Option<OrderRequest>,
}

/// The fields of a VDA 5050 order that the path does not decide ([`OrderParams`]).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct OrderRequest {
    #[serde(default, deserialize_with = "present")]
    order_id: Option<String>,
    #[serde(default, deserialize_with = "present")]
    order_update_id: Option<u32>,
    #[serde(default, deserialize_with = "present")]
    header_id: Option<u32>,
    #[serde(default, deserialize_with = "present")]
    manufacturer: Option<String>,
    #[serde(default, deserialize_with = "present")]
    serial_number: Option<String>,
    #[serde(default, deserialize_with = "present")]
    map_id: Option<String>,
    #[serde(default, deserialize_with = "present")]
    release_margin: Option<f64>,
}

impl From<OrderRequest> for OrderParams {
    fn from(r: OrderRequest) -> OrderParams {
        OrderParams {
            header: Header {
                header_id: r.header_id.unwrap_or(0),
                manufacturer: r.manufacturer.unwrap_or_default(),
                serial_number: r.serial_number.unwrap_or_default(),
                map_id: r.map_id,
            },
            order_id: r.order_id,
            order_update_id: r.order_update_id.unwrap_or(0),
            release_margin: r.release_margin.unwrap_or(0.0),
        }
    }
}

/// The media type of a path written as a ROS 2 `nav_msgs/Path` message (JSON).
pub(super) const NAV_MSGS_PATH_JSON: &str = "application/vnd.ros.nav-msgs.path+json";

/// The media type of a path written as a VDA 5050 order.
pub(super) const VDA5050_ORDER_JSON: &str = "application/vnd.vda5050.order+json";

/// The format an `Accept` header asks a path in: CSV (`text/csv`), a `nav_msgs/Path`
/// ([`NAV_MSGS_PATH_JSON`]), a VDA 5050 order ([`VDA5050_ORDER_JSON`]), or else the path answer
/// (JSON). The first of those named wins.
fn route_format(headers: &HeaderMap) -> RouteFormat {
    let accept = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(|range| {
            range
                .split(';')
                .next()
                .unwrap_or("")
                .trim()
                .to_ascii_lowercase()
        });
    for media in accept {
        match media.as_str() {
            "text/csv" => return RouteFormat::Csv,
            NAV_MSGS_PATH_JSON => return RouteFormat::NavMsgsPath,
            VDA5050_ORDER_JSON => return RouteFormat::Vda5050Order,
            _ => {}
        }
    }
    RouteFormat::Json
}

/// The map a path or sweep query names, or the 202 answer while it is built.
pub(super) async fn map_for_query(
    state: &App,
    caller: &Caller,
    map_id: Option<MapId>,
    map: Option<MapRequest>,
) -> Result<Result<(Arc<RadioMap>, Arc<Scenario>), Response>, Error> {
    match (map_id, map) {
        (Some(id), None) => Ok(Ok(state.map_with_scenario(caller, &id).await?)),
        (None, Some(request)) => Ok(
            match state.request_map(caller, request.spec(), "map.").await? {
                Obtained::Ready { map, scenario } => Ok((map, scenario)),
                Obtained::Building(job) => Err(accepted(*job)),
            },
        ),
        _ => Err(Error::invalid(
            "map_id",
            "give exactly one of map_id and map",
        )),
    }
}

pub(super) fn check_point(field: &'static str, p: [f64; 2]) -> Result<[f64; 2], Error> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(p)
    } else {
        Err(Error::invalid(field, "coordinates must be finite"))
    }
}

pub(super) async fn plan_path(
    State(state): State<App>,
    caller: Caller,
    headers: HeaderMap,
    Body(request): Body<PathRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let start = check_point("start", request.start)?;
    let goal = check_point("goal", request.goal)?;
    let limit = state.limits().max_draws;
    if let Some(draws) = request.monte_carlo_draws
        && (draws == 0 || draws > limit)
    {
        return Err(Error::limit_exceeded(
            "monte_carlo_draws",
            limit as u64,
            format!("must lie in 1..={limit}"),
        )
        .into());
    }
    if request
        .seed
        .is_some_and(|seed| seed > MAX_JSON_SAFE_INTEGER)
    {
        return Err(Error::limit_exceeded(
            "seed",
            MAX_JSON_SAFE_INTEGER,
            "must be at most 2^53 − 1, the largest integer every JSON client keeps exact",
        )
        .into());
    }
    let tolerance_m = request.tolerance_m.unwrap_or(0.0);
    if !(0.0..=planner::MAX_TOLERANCE_M).contains(&tolerance_m) {
        return Err(Error::invalid(
            "tolerance_m",
            format!("must lie in [0, {}] m", planner::MAX_TOLERANCE_M),
        )
        .into());
    }
    let route_format = route_format(&headers);
    if route_format != RouteFormat::Json && request.monte_carlo_draws.is_some() {
        return Err(Error::invalid(
            "monte_carlo_draws",
            "a Monte Carlo report is part of the JSON path answer only (Accept: application/json)",
        )
        .into());
    }
    let order = match request.order {
        Some(_) if route_format != RouteFormat::Vda5050Order => {
            return Err(Error::invalid(
                "order",
                format!("applies only to a VDA 5050 order (Accept: {VDA5050_ORDER_JSON})"),
            )
            .into());
        }
        given => OrderParams::from(given.unwrap_or_default()),
    };
    order.validate()?;
    let (format, precision) = path::phase_options(request.phase_format, request.phase_precision)?;
    let found = map_for_query(&state, &caller, request.map_id, request.map).await?;
    let (map, scenario) = match found {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let map_id = MapId::of_map(&map);
    let unit = request.unit.unwrap_or(map.native_unit());
    let options = planner::PathOptions {
        shape: request.path_shape.unwrap_or_default(),
        tolerance_m,
    };
    // A plain query asked before is answered from the answer cache (`app::answers`).
    let frame = request.frame_id.unwrap_or_default();
    let query =
        (request.monte_carlo_draws.is_none() && route_format == RouteFormat::Json).then(|| {
            PathQuery::new(
                map_id.clone(),
                start,
                goal,
                (request.threshold, unit, options),
                (format, precision),
                frame.clone(),
            )
        });
    if let Some(kept) = query.as_ref().and_then(|q| state.answers().get(q)) {
        return Ok(json::with_took_ms(kept.open_text(), started));
    }
    let cells = map.grid.cells();
    let (threshold, v_max) = (request.threshold, scenario.mru.v_max_mps);
    let (planned, cache) = (map.clone(), state.cache().clone());
    let on_graph = scenario.clone();
    // A route-graph path scores every edge of the graph first (a few dozen cells each).
    let work = match options.shape {
        PathShape::RouteGraph => {
            let edges = scenario.route_graph.as_ref().map_or(0, |g| g.edges.len());
            cells.saturating_add(edges.saturating_mul(64))
        }
        _ => cells,
    };
    let path = heavy(&state, "path", work, move |_| {
        let index = cache.unit_index(&map_id, &planned, unit)?;
        match options.shape {
            PathShape::RouteGraph => path::plan_on_route_graph(
                &on_graph,
                &planned,
                (unit, index.values(&planned)),
                tolerance_m,
                start,
                goal,
                threshold,
            ),
            _ => planner::plan_indexed(&planned, &index, options, start, goal, threshold, v_max),
        }
    })
    .await??;
    // Written before the Monte Carlo check, which then evaluates the phases as sent.
    let mut path = path::write_phases(&scenario, &map, path, format, precision);
    path.frame_id = frame.as_str().to_string();
    match route_format {
        RouteFormat::Json => {}
        RouteFormat::NavMsgsPath => {
            let media = [(header::CONTENT_TYPE, NAV_MSGS_PATH_JSON)];
            return Ok((media, Json(route::nav_msgs_path(&path))).into_response());
        }
        RouteFormat::Csv => {
            let csv = [(header::CONTENT_TYPE, "text/csv; charset=utf-8")];
            return Ok((csv, route::csv(&path)).into_response());
        }
        RouteFormat::Vda5050Order => {
            let order = vda5050::order(&path, &order, SystemTime::now())?;
            let media = [(header::CONTENT_TYPE, VDA5050_ORDER_JSON)];
            return Ok((media, Json(order)).into_response());
        }
    }
    let monte_carlo = match request.monte_carlo_draws {
        Some(draws) if path.feasible => {
            let rate = map.key.kind == MapKind::Rate;
            let estimated_s =
                montecarlo::check_seconds(&scenario, path.waypoints.len(), draws, rate);
            check_budget(
                "monte_carlo_draws",
                "Monte Carlo check",
                estimated_s,
                state.limits().max_check_cpu_s,
            )?;
            let seed = request.seed.unwrap_or(1);
            if estimated_s > SYNC_CHECK_S {
                // Longer than a request should wait: a job with progress and cancel, its
                // answer (this body with the report) at the job's `result_href`.
                let scenario_id = ScenarioId::of_key(&map.key);
                let job = state.jobs().answer(
                    AnswerKind::Check,
                    scenario_id,
                    caller.owner(),
                    move |progress| {
                        let started = Instant::now();
                        let report = path::check(&scenario, &map, &path, draws, seed, progress)?;
                        let checked = CheckedPath {
                            path,
                            monte_carlo: Some(report),
                        };
                        let mut answer: serde_json::Value =
                            serde_json::from_slice(&checked.to_json()).expect("answers are JSON");
                        answer["took_ms"] = serde_json::json!(timing::took_ms(started));
                        Ok(answer)
                    },
                )?;
                return Ok(accepted(job.view()));
            }
            let (scenario, map, path) = (scenario.clone(), map.clone(), path.clone());
            // Thousands of draws per waypoint: always a heavy query, cancelled with its client.
            let report = state
                .queries()
                .run("Monte Carlo check", move |progress| {
                    path::check(&scenario, &map, &path, draws, seed, progress)
                })
                .await?
                .map_err(|e| Error::internal(e.to_string()))?;
            Some(report)
        }
        _ => None,
    };
    let answer = OpenAnswer::new(CheckedPath { path, monte_carlo }.to_json())?;
    if let Some(query) = query {
        state.answers().insert(query, answer.clone());
    }
    Ok(json::with_took_ms(answer.open_text(), started))
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SweepRequest {
    #[serde(default, deserialize_with = "present")]
    map_id: Option<MapId>,
    #[serde(default, deserialize_with = "present")]
    map: Option<MapRequest>,
    start: [f64; 2],
    goal: [f64; 2],
    thresholds: Vec<f64>,
    /// The unit of the thresholds (default: the map's own).
    #[serde(default, deserialize_with = "present")]
    unit: Option<Unit>,
}

pub(super) async fn sweep(
    State(state): State<App>,
    caller: Caller,
    Body(request): Body<SweepRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let start = check_point("start", request.start)?;
    let goal = check_point("goal", request.goal)?;
    let limit = state.limits().max_sweep;
    if request.thresholds.is_empty() || request.thresholds.len() > limit {
        return Err(Error::limit_exceeded(
            "thresholds",
            limit as u64,
            format!("give 1 to {limit} thresholds"),
        )
        .into());
    }
    if let Some(k) = request.thresholds.iter().position(|t| !t.is_finite()) {
        return Err(Error::invalid(format!("thresholds[{k}]"), "must be a finite number").into());
    }
    let found = map_for_query(&state, &caller, request.map_id, request.map).await?;
    let (map, scenario) = match found {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let (cells, v_max, thresholds) = (map.grid.cells(), scenario.mru.v_max_mps, request.thresholds);
    let unit = request.unit.unwrap_or(map.native_unit());
    // A sweep is one search per threshold: heavy once thresholds × cells is, not cells alone.
    let work = cells.saturating_mul(thresholds.len());
    let cache = state.cache().clone();
    let answer: SweepAnswer = heavy(&state, "sweep", work, move |progress| {
        let index = cache.unit_index(&MapId::of_map(&map), &map, unit)?;
        planner::sweep(&map, &index, start, goal, &thresholds, v_max, progress)
    })
    .await?
    .map_err(|e| match e {
        WorkError::Invalid(e) => Error::from(e),
        WorkError::Cancelled(c) => Error::internal(c.to_string()),
    })?;
    Ok(Json(Timed::since(started, answer)).into_response())
}

/// `GET /v1/checks/{check_id}`: a Monte Carlo check that ran as a job — the path answer with
/// its report, once the job is done.
pub(super) async fn get_check(
    State(state): State<App>,
    caller: Caller,
    Path(check_id): Path<JobId>,
) -> Result<Response, ApiError> {
    super::jobs::answer_of(&state, &caller, &check_id, AnswerKind::Check)
}
