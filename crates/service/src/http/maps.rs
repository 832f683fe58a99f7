//! `/v1/maps`: request a map (built at once when cheap, else as a job answered 202), list the
//! cached ones, read one's body and delete it; and the map acquisition the path, sweep and
//! export handlers share (a map by id, or by the request defining it).

use super::problem::ApiError;
use super::scenarios::parse_scenario;
use super::{Body, Page, accepted, check_budget, heavy};
use crate::AppState;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::cluster::Cluster;
use crate::jobs::{JobRecord, JobState, MapRequestOutcome};
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use irs_answers::timing::Timed;
use irs_model::input::present;
use irs_model::phases::PhaseMode;
use irs_model::radiomap::cost;
use irs_model::radiomap::{MapKey, MapKind, MapStats, RadioMap};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;
use irs_model::solver::SolverKind;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::Arc;
use std::time::Instant;

/// What defines a map: a scenario (registered id or inline document) and the map parameters.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MapRequest {
    #[serde(default, deserialize_with = "present")]
    pub(super) scenario_id: Option<String>,
    #[serde(default, deserialize_with = "present")]
    pub(super) scenario: Option<serde_json::Map<String, serde_json::Value>>,
    kind: MapKind,
    #[serde(default, deserialize_with = "present")]
    phases: Option<PhaseMode>,
    #[serde(default, deserialize_with = "present")]
    access: Option<Access>,
    #[serde(default, deserialize_with = "present")]
    solver: Option<SolverKind>,
}

#[derive(Debug, Serialize)]
pub(super) struct MapSummary {
    map_id: String,
    state: &'static str,
    key: MapKey,
    unit: &'static str,
    stats: MapStats,
    build_seconds: f64,
    href: String,
}

pub(super) fn summary(map: &RadioMap) -> MapSummary {
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
pub(super) async fn fetch_scenario(
    state: &AppState,
    scenario_id: Option<&str>,
) -> Result<(), Error> {
    if let Some(id) = scenario_id
        && state.cluster().is_some()
    {
        state.shared_scenario(id).await?;
    }
    Ok(())
}

/// The scenario a request names: a registered one by `scenario_id`, or an inline document
/// (`inline` true: register it once the whole request is valid). Returns its id too.
pub(super) fn scenario_of(
    state: &AppState,
    scenario_id: Option<String>,
    scenario: Option<serde_json::Map<String, serde_json::Value>>,
    prefix: &str,
) -> Result<(String, Arc<Scenario>, bool), Error> {
    match (scenario_id, scenario) {
        (Some(id), None) => {
            // An unknown id is "not found" (404), as an unknown map_id is, naming the field.
            let stored = state.registry().get(&id).ok_or_else(|| {
                Error::not_found("scenario", &id).with_field(format!("{prefix}scenario_id"))
            })?;
            Ok((id, stored.scenario.clone(), false))
        }
        (None, Some(doc)) => {
            let scenario = parse_scenario(doc.into(), &format!("{prefix}scenario."))?;
            Ok((scenario.content_hash(), Arc::new(scenario), true))
        }
        _ => Err(Error::invalid(
            format!("{prefix}scenario_id"),
            "give exactly one of scenario_id (a registered scenario) and scenario (an inline document)",
        )),
    }
}

/// Resolves a map request to a scenario and a normalised key, and checks the build's estimated
/// cost against the budget. An inline scenario is registered (for `caller`) only once the whole
/// request has been validated, so a rejected request leaves no trace.
pub(super) fn resolve(
    state: &AppState,
    caller: &Caller,
    request: MapRequest,
    prefix: &str,
) -> Result<(Arc<Scenario>, MapKey), Error> {
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
        return Err(Error::limit_exceeded(
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
        return Err(Error::limit_exceeded(
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

/// The map, waiting for cheap builds; `Err(Response)` is the 202 job answer for long ones.
pub(super) async fn obtain(
    state: &AppState,
    caller: &Caller,
    scenario: Arc<Scenario>,
    key: MapKey,
) -> Result<Result<Arc<RadioMap>, Response>, Error> {
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
                None => Err(Error::BuildFailed(job.view().error.unwrap_or_else(|| {
                    format!("job {} ended {} without a map", job.id, job.state().label())
                }))),
            }
        }
        MapRequestOutcome::Building(job) => Ok(Err(accepted(job.view()))),
    }
}

/// [`obtain`] in a cluster: the map from any replica's build. The build is queued in the
/// shared stream (once for the whole cluster) and runs on whichever replica has a free worker;
/// a cheap one is waited for by polling its record.
pub(super) async fn obtain_shared(
    state: &AppState,
    cluster: &Cluster,
    caller: &Caller,
    key: MapKey,
    cheap: bool,
) -> Result<Result<Arc<RadioMap>, Response>, Error> {
    let map_id = key.id();
    if let Some(map) = state.shared_map(&map_id).await? {
        return Ok(Ok(map));
    }
    // The replica that builds it reads the scenario from the shared store.
    let stored = state
        .shared_scenario(&key.scenario_id)
        .await?
        .ok_or_else(|| Error::not_found("scenario", &key.scenario_id))?;
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
                    None => Err(Error::BuildFailed(format!(
                        "job {job_id} is done but its map is in no store"
                    ))),
                };
            }
            s if s.is_terminal() => {
                return Err(Error::BuildFailed(current.error.unwrap_or_else(|| {
                    format!("job {job_id} ended {} without a map", s.label())
                })));
            }
            _ => tokio::time::sleep(SHARED_POLL).await,
        }
    }
}

/// How often a request waiting for another replica's build reads its record: a gain map of
/// the sizes built inline takes tens of milliseconds, so the wait adds at most this.
pub(super) const SHARED_POLL: std::time::Duration = std::time::Duration::from_millis(20);

pub(super) async fn request_map(
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
pub(super) struct MapList {
    maps: Vec<MapSummary>,
    /// The cursor of the next page, or null on the last.
    next_cursor: Option<String>,
}

/// The cached maps, by id, a page at a time.
pub(super) async fn list_maps(
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

pub(super) async fn cached_map(state: &AppState, map_id: &str) -> Result<Arc<RadioMap>, Error> {
    if let Some(map) = state.shared_map(map_id).await? {
        return Ok(map);
    }
    if let Some(job) = state.jobs().building(map_id).await {
        return Err(Error::MapNotReady {
            map_id: map_id.to_string(),
            job_id: job.id.clone(),
        });
    }
    if let Some(cluster) = state.cluster()
        && let Some(job_id) = cluster.building(map_id).await?
    {
        return Err(Error::MapNotReady {
            map_id: map_id.to_string(),
            job_id,
        });
    }
    Err(Error::not_found("map", map_id))
}

/// Drops a cached map (the next request for it builds it again). A map being built answers
/// 409 with its job: cancel the job instead.
pub(super) async fn delete_map(
    State(state): State<AppState>,
    Path(map_id): Path<String>,
) -> Result<StatusCode, ApiError> {
    if let Some(job) = state.jobs().building(&map_id).await {
        return Err(Error::MapNotReady {
            map_id,
            job_id: job.id.clone(),
        }
        .into());
    }
    let mut removed = state.cache().remove(&map_id).await;
    if let Some(cluster) = state.cluster() {
        removed |= cluster.delete_map(&map_id).await?;
    }
    if !removed {
        return Err(Error::not_found("map", &map_id).into());
    }
    tracing::info!(map_id = %map_id, "map deleted");
    Ok(StatusCode::NO_CONTENT)
}

/// A built map and the scenario it was built from.
pub(super) async fn map_and_scenario(
    state: &AppState,
    map_id: &str,
) -> Result<(Arc<RadioMap>, Arc<Scenario>), Error> {
    let map = cached_map(state, map_id).await?;
    let stored = state
        .shared_scenario(&map.key.scenario_id)
        .await?
        .ok_or_else(|| Error::not_found("scenario", &map.key.scenario_id))?;
    Ok((map, stored.scenario.clone()))
}

pub(super) async fn get_map(
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
    let bytes = bytes.map_err(|e| Error::internal(format!("serialising the map: {e}")))?;
    Ok(([(header::CONTENT_TYPE, "application/json")], bytes).into_response())
}
