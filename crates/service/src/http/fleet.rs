//! `/v1/fleet-plans`: several robots planned at once on a built gain map (docs/model.md §6.5):
//! checked field by field first, then answered while the request waits on the query workers
//! (admission as for paths) or, when large or asked to (`Prefer: respond-async`), run as a job
//! whose plan is read at `/v1/fleet-plans/{id}`.

use super::json::serialize_sized;
use super::maps::MapRequest;
use super::paths::map_for_query;
use super::problem::ApiError;
use super::{Body, accepted, heavy};
use crate::app::identity::Caller;
use crate::app::jobs::AnswerKind;
use crate::app::{App, Error};
use crate::ids::{JobId, MapId, ScenarioId};
use axum::extract::{Path, State};
use axum::http::{HeaderMap, header};
use axum::response::{IntoResponse, Response};
use irs_answers::fleet::{self, FleetQuery, RobotSpec};
use irs_answers::timing::{self, Timed};
use irs_model::input::present;
use irs_model::radiomap::{Unit, WorkError};
use irs_model::rate::Access;
use serde::Deserialize;
use std::time::Instant;

/// A fleet plan names its map by `map_id` (a built map) or `map` (the request defining it);
/// the rest is the [`FleetQuery`] the CLI reads from a file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FleetRequest {
    #[serde(default, deserialize_with = "present")]
    map_id: Option<MapId>,
    #[serde(default, deserialize_with = "present")]
    map: Option<MapRequest>,
    robots: Vec<RobotSpec>,
    #[serde(default, deserialize_with = "present")]
    unit: Option<Unit>,
    #[serde(default, deserialize_with = "present")]
    dt_s: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    horizon_s: Option<f64>,
    #[serde(default, deserialize_with = "present")]
    access: Option<Access>,
}

/// Plans whose robots × cells exceed this many times `--sync-cells` run as jobs (202): a
/// robot's search touches each cell a few times, so this is a few gain maps' worth of work,
/// a second or so. 8 robots on the 0.25 m warehouse (0.3 M) are answered at once.
pub(super) const SYNC_FLEET_MAPS: usize = 4;

/// Whether the client asked for a job whatever the size: `Prefer: respond-async` (RFC 7240).
fn prefers_async(headers: &HeaderMap) -> bool {
    headers.get_all("prefer").iter().any(|value| {
        value.to_str().is_ok_and(|v| {
            v.split(',')
                .any(|p| p.trim().eq_ignore_ascii_case("respond-async"))
        })
    })
}

pub(super) async fn plan_fleet(
    State(state): State<App>,
    caller: Caller,
    headers: HeaderMap,
    Body(request): Body<FleetRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let found = map_for_query(&state, &caller, request.map_id, request.map).await?;
    let (map, scenario) = match found {
        Ok(found) => found,
        Err(accepted) => return Ok(accepted),
    };
    let query = FleetQuery {
        robots: request.robots,
        unit: request.unit,
        dt_s: request.dt_s,
        horizon_s: request.horizon_s,
        access: request.access,
    };
    // Each robot's search touches at most every cell a bounded number of times.
    let work = map.grid.cells().saturating_mul(query.robots.len().max(1));
    // Every field checked before any search: a bad one is a 422 now, never a failed job. The
    // checks include each robot's route alone, a search of the map per robot: weighed as such.
    let (checked_scenario, checked_map, checked_query) =
        (scenario.clone(), map.clone(), query.clone());
    heavy(&state, "fleet check", work, move |_| {
        fleet::check(&checked_scenario, &checked_map, &checked_query)
    })
    .await??;
    let asked = prefers_async(&headers);
    if asked || work > SYNC_FLEET_MAPS.saturating_mul(state.limits().sync_cells) {
        let scenario_id = ScenarioId::of_key(&map.key);
        let job = state.jobs().answer(
            AnswerKind::Fleet,
            scenario_id,
            caller.owner(),
            move |progress| {
                let started = Instant::now();
                let answer = fleet::plan(&scenario, &map, &query, progress)?;
                let mut answer = serde_json::to_value(&answer).expect("answers serialise");
                answer["took_ms"] = serde_json::json!(timing::took_ms(started));
                Ok(answer)
            },
        )?;
        let mut response = accepted(job.view());
        if asked {
            response.headers_mut().insert(
                "preference-applied",
                header::HeaderValue::from_static("respond-async"),
            );
        }
        return Ok(response);
    }
    let answer = heavy(&state, "fleet plan", work, move |progress| {
        fleet::plan(&scenario, &map, &query, progress)
    })
    .await?
    .map_err(|e| match e {
        WorkError::Invalid(e) => Error::from(e),
        WorkError::Cancelled(c) => Error::internal(c.to_string()),
    })?;
    let steps = answer.plan.timeline.len();
    let phases = answer
        .plan
        .timeline
        .first()
        .map_or(0, |i| i.phases.iter().map(Vec::len).sum());
    let capacity = 1024 + steps * (answer.plan.robots.len() * 200 + phases * 8);
    let body = serialize_sized(&Timed::since(started, &answer), capacity)?;
    Ok(([(header::CONTENT_TYPE, "application/json")], body).into_response())
}

/// `GET /v1/fleet-plans/{plan_id}`: a fleet plan that ran as a job, once it is done.
pub(super) async fn get_fleet_plan(
    State(state): State<App>,
    caller: Caller,
    Path(plan_id): Path<JobId>,
) -> Result<Response, ApiError> {
    super::jobs::answer_of(&state, &caller, &plan_id, AnswerKind::Fleet)
}
