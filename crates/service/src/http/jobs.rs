//! `/v1/jobs`: the caller's jobs, one job's state (here, or another replica's from its
//! record), and cancellation (here, or through the shared store).

use super::Page;
use super::problem::ApiError;
use crate::AppState;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::jobs::JobView;
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

pub(super) async fn get_job(
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
    Err(Error::not_found("job", &id).into())
}

pub(super) async fn cancel_job(
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
            .ok_or_else(|| Error::not_found("job", &id))?;
        if record.state.is_terminal() {
            return Err(Error::JobFinished {
                job_id: id,
                state: record.state.label(),
            }
            .into());
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
