//! `/v1/jobs`: the caller's jobs, one job's state (here, or another replica's from its
//! record), and cancellation (here, or through the shared store).

use super::Page;
use super::problem::ApiError;
use crate::app::App;
use crate::app::identity::Caller;
use crate::app::jobs::JobView;
use crate::ids::JobId;
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::StatusCode;
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
