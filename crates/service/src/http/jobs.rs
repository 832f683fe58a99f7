//! `/v1/jobs`: the caller's jobs, one job's state (here, or another replica's from its
//! record), and cancellation (here, or through the shared store).

use super::Page;
use super::problem::ApiError;
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::app::jobs::{AnswerKind, JobView};
use crate::ids::JobId;
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use std::collections::HashMap;

#[derive(Serialize)]
pub(super) struct JobList {
    jobs: Vec<JobView>,
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The caller's jobs (all jobs with authentication off), newest first, a page at a time.
pub(super) async fn list_jobs(
    State(state): State<App>,
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

pub(super) async fn get_job(
    State(state): State<App>,
    caller: Caller,
    Path(id): Path<JobId>,
) -> Result<Json<JobView>, ApiError> {
    Ok(Json(state.job(&caller, &id).await?))
}

pub(super) async fn cancel_job(
    State(state): State<App>,
    caller: Caller,
    Path(id): Path<JobId>,
) -> Result<(StatusCode, Json<JobView>), ApiError> {
    Ok((
        StatusCode::ACCEPTED,
        Json(state.cancel_job(&id, &caller).await?),
    ))
}

/// The answer of a job of `kind` (a Monte Carlo check, a fleet plan) once it is done: 404 for a
/// job of another kind or another tenant, 409 while it runs or when it ended without one.
pub(super) fn answer_of(
    state: &App,
    caller: &Caller,
    id: &JobId,
    kind: AnswerKind,
) -> Result<Response, ApiError> {
    let (what, not_ready): (&'static str, fn(JobId) -> Error) = match kind {
        AnswerKind::Check => ("check", |job_id| Error::CheckNotReady { job_id }),
        AnswerKind::Fleet => ("fleet plan", |job_id| Error::FleetPlanNotReady { job_id }),
    };
    let job = state
        .jobs()
        .get(id)
        .filter(|j| j.kind() == kind.job_kind() && j.visible_to(caller))
        .ok_or_else(|| Error::not_found(what, id))?;
    match job.answer(kind) {
        Some(outcome) => Ok(Json(&outcome.answer).into_response()),
        None if job.state().is_terminal() => Err(Error::JobFinished {
            job_id: job.id.clone(),
            state: job.state(),
        }
        .into()),
        None => Err(not_ready(job.id.clone()).into()),
    }
}
