//! `/v1/fleet-plans`: several robots planned at once on a built gain map (docs/model.md §6.5),
//! answered while the request waits, on the query workers (admission as for paths).

use super::json::serialize_sized;
use super::maps::MapRequest;
use super::paths::map_for_query;
use super::problem::ApiError;
use super::{Body, heavy};
use crate::app::identity::Caller;
use crate::app::{App, Error};
use crate::ids::MapId;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use irs_answers::fleet::{self, FleetQuery, RobotSpec};
use irs_answers::timing::Timed;
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

pub(super) async fn plan_fleet(
    State(state): State<App>,
    caller: Caller,
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
