//! `/v1/scenarios`: register a scenario document, list the ones the caller may see, read one
//! (here or, in a cluster, from another replica) and delete a registration.

use super::problem::ApiError;
use super::{Body, Page};
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::app::registry::ScenarioSummary;
use crate::app::scenarios::parse_scenario;
use crate::ids::ScenarioId;
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use irs_model::scenario::Scenario;
use serde::Serialize;
use std::collections::HashMap;

#[derive(Serialize)]
pub(super) struct ScenarioList {
    scenarios: Vec<ScenarioSummary>,
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The scenarios the caller may see (the server's own and, with authentication on, the
/// caller's), by id, a page at a time.
pub(super) async fn list_scenarios(
    State(state): State<App>,
    caller: Caller,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Json<ScenarioList>, ApiError> {
    let page = Page::of(&query)?;
    let listed = state.registry().list(&caller);
    let keyed = listed.into_iter().map(|s| (s.id.to_string(), s)).collect();
    let (scenarios, next_cursor) = page.cut(keyed, |key, cursor| key > cursor);
    Ok(Json(ScenarioList {
        scenarios,
        next_cursor,
    }))
}

#[derive(Serialize)]
pub(super) struct ScenarioDocument {
    #[serde(flatten)]
    summary: ScenarioSummary,
    scenario: Scenario,
}

pub(super) async fn register_scenario(
    State(state): State<App>,
    caller: Caller,
    Body(value): Body<serde_json::Value>,
) -> Result<Response, ApiError> {
    let scenario = parse_scenario(value, "")?;
    let (stored, created) = state.add_scenario(scenario, &caller).await?;
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

pub(super) async fn get_scenario(
    State(state): State<App>,
    caller: Caller,
    Path(id): Path<ScenarioId>,
) -> Result<Json<ScenarioDocument>, ApiError> {
    let stored = state
        .visible_scenario(&caller, &id)
        .await?
        .ok_or_else(|| Error::not_found("scenario", &id))?;
    Ok(Json(ScenarioDocument {
        summary: stored.summary(),
        scenario: (*stored.scenario).clone(),
    }))
}

/// Deletes the caller's registration of an API scenario; with the last registration the
/// scenario goes, and the cached maps built from it. A scenario that a queued or running job
/// needs is kept (409 with the job).
pub(super) async fn delete_scenario(
    State(state): State<App>,
    caller: Caller,
    Path(id): Path<ScenarioId>,
) -> Result<StatusCode, ApiError> {
    state.delete_scenario(&id, &caller).await?;
    Ok(StatusCode::NO_CONTENT)
}
