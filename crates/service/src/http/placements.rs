//! `/v1/placements`: a placement search for an IRS or an access point (answered at once when
//! small, else as a job), and its answer once the job is done.

use super::problem::ApiError;
use super::{Body, accepted};
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::app::jobs::{Job, PlacementOutcome, PlacementSearch, Work};
use crate::app::maps::check_budget;
use crate::app::registry::ScenarioSource;
use crate::app::scenarios::{Named, ScenarioRef};
use crate::ids::{JobId, ScenarioId};
use axum::Json;
use axum::extract::{Path, State};
use axum::response::{IntoResponse, Response};
use irs_answers::timing::Timed;
use irs_model::input::present;
use irs_model::phases::PhaseMode;
use irs_model::placement::{self, Candidates, Objective, Search, What};
use irs_model::radiomap::cost;
use serde::{Deserialize, Serialize};
use std::time::Instant;

/// A placement search: the scenario (by id or inline) and the search (docs/model.md §7).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct PlacementRequest {
    #[serde(default, deserialize_with = "present")]
    scenario_id: Option<ScenarioId>,
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
pub(super) const DEFAULT_KEEP: usize = 3;
pub(super) const MAX_KEEP: usize = 20;

/// Searches small enough (candidates × cells × APs) are answered while the request waits, as
/// gain maps of up to `sync_cells` cells are; a candidate's cell costs about what a gain-map
/// cell does, and four maps' worth is still well under a second.
pub(super) const SYNC_PLACEMENT_MAPS: usize = 4;
/// ... unless its estimated CPU says otherwise: a floor plan makes each cell's blockage tests
/// walk thousands of pixels, and a search of few cells then takes minutes.
const SYNC_PLACEMENT_S: f64 = 2.0;

/// A placement answer as the API returns it: the search's answer (the CLI's body), the job it
/// ran as and how many of the best candidates are registered with their maps cached.
#[derive(Serialize)]
pub(super) struct PlacementBody<'a> {
    placement_id: &'a JobId,
    #[serde(flatten)]
    answer: &'a serde_json::Value,
    registered: usize,
    href: String,
}

pub(super) fn placement_body<'a>(job: &'a Job, outcome: &'a PlacementOutcome) -> PlacementBody<'a> {
    PlacementBody {
        placement_id: &job.id,
        answer: &outcome.answer,
        registered: outcome.registered,
        href: job.id.placement_href(),
    }
}

pub(super) async fn place(
    State(state): State<App>,
    caller: Caller,
    Body(request): Body<PlacementRequest>,
) -> Result<Response, ApiError> {
    let started = Instant::now();
    let keep = request.keep.unwrap_or(DEFAULT_KEEP);
    if keep > MAX_KEEP {
        return Err(Error::limit_exceeded(
            "keep",
            MAX_KEEP as u64,
            format!("at most {MAX_KEEP} candidates are registered"),
        )
        .into());
    }
    let reference = ScenarioRef {
        id: request.scenario_id,
        document: request.scenario,
    };
    let Named {
        scenario, inline, ..
    } = state.named_scenario(&caller, reference, "").await?;
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
    let estimated_s =
        cost::gain_seconds(&scenario, cell_evaluations, mode, cost::Evaluation::Cells);
    check_budget(
        "candidates",
        "placement search",
        estimated_s,
        state.limits().max_build_cpu_s,
    )?;
    if inline {
        state
            .register_api_scenario(scenario.clone(), &caller)
            .await?;
    }
    let work = candidates.len() * scenario.grid().cells() * scenario.access_points().len();
    let (registrar, owner) = (state.clone(), caller.clone());
    let (claimant, claimer) = (state.clone(), caller.clone());
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
                .register_scenario(s, ScenarioSource::Api, &owner)
                .inspect_err(
                    |e| tracing::warn!(error = %e, "a placement candidate was not registered"),
                )
                .is_ok()
        },
        // The best candidates' maps are the caller's, as if it had asked for each.
        move |map_id| {
            let (state, caller) = (claimant.clone(), claimer.clone());
            Box::pin(async move {
                if let Err(e) = state.claim_map(&caller, &map_id).await {
                    tracing::warn!(error = %e, "a placement candidate's map was not claimed");
                }
            })
        },
    )?;
    if work > SYNC_PLACEMENT_MAPS * state.limits().sync_cells || estimated_s > SYNC_PLACEMENT_S {
        return Ok(accepted(job.view()));
    }
    job.finished().await;
    let outcome = job.placement().ok_or_else(|| {
        Error::BuildFailed(
            job.view()
                .error
                .unwrap_or_else(|| format!("job {} did not finish", job.id)),
        )
    })?;
    Ok(Json(Timed::since(started, placement_body(&job, &outcome))).into_response())
}

pub(super) async fn get_placement(
    State(state): State<App>,
    caller: Caller,
    Path(placement_id): Path<JobId>,
) -> Result<Response, ApiError> {
    let job = state
        .jobs()
        .get(&placement_id)
        .filter(|j| matches!(j.work, Work::Placement { .. }) && j.visible_to(&caller))
        .ok_or_else(|| Error::not_found("placement", &placement_id))?;
    match job.placement() {
        Some(outcome) => Ok(Json(placement_body(&job, &outcome)).into_response()),
        None if job.state().is_terminal() => Err(Error::JobFinished {
            job_id: job.id.clone(),
            state: job.state(),
        }
        .into()),
        None => Err(Error::PlacementNotReady {
            job_id: job.id.clone(),
        }
        .into()),
    }
}
