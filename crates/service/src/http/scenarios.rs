//! `/v1/scenarios`: register a scenario document, list the ones the caller may see, read one
//! (here or, in a cluster, from another replica) and delete a registration.

use super::problem::ApiError;
use super::{Body, Page};
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::app::registry::{ScenarioSummary, StoredScenario};
use crate::ids::ScenarioId;
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use irs_answers::scenario::Document;
use serde::Serialize;
use std::collections::HashMap;
use std::sync::Arc;

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
struct ScenarioAnswer {
    #[serde(flatten)]
    summary: ScenarioSummary,
    scenario: Document,
}

/// A scenario's answer (its summary and document), serialised on the query pool when it
/// carries a big floor plan (its image is megabytes of base64).
async fn scenario_answer(state: &App, stored: Arc<StoredScenario>) -> Result<Vec<u8>, ApiError> {
    let body = state
        .queries()
        .run_sized("scenario", stored.scenario.raster_bytes(), move || {
            serde_json::to_vec(&ScenarioAnswer {
                summary: stored.summary(),
                scenario: Document::from(&*stored.scenario),
            })
        })
        .await?
        .map_err(|e| Error::internal(format!("scenario answer: {e}")))?;
    Ok(body)
}

const JSON: (header::HeaderName, &str) = (header::CONTENT_TYPE, "application/json");

pub(super) async fn register_scenario(
    State(state): State<App>,
    caller: Caller,
    Body(value): Body<serde_json::Value>,
) -> Result<Response, ApiError> {
    let (stored, created) = state.add_scenario(value, &caller).await?;
    let status = if created {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    let location = stored.summary().href;
    let body = scenario_answer(&state, stored).await?;
    Ok((status, [JSON, (header::LOCATION, location.as_str())], body).into_response())
}

pub(super) async fn get_scenario(
    State(state): State<App>,
    caller: Caller,
    Path(id): Path<ScenarioId>,
) -> Result<Response, ApiError> {
    let stored = state
        .visible_scenario(&caller, &id)
        .await?
        .ok_or_else(|| Error::not_found("scenario", &id))?;
    let body = scenario_answer(&state, stored).await?;
    Ok(([JSON], body).into_response())
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
