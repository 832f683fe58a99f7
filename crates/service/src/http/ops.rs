//! The operations endpoints: `/healthz` (the process answers), `/readyz` (started and not
//! stopping; 200 `degraded` naming what it works without, e.g. an unreachable Redis or an
//! unwritable data directory, so a load balancer keeps routing to it), `/version` and
//! `/metrics` (Prometheus text).

use super::problem::ApiError;
use crate::app::{App, Component};
use axum::Json;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use irs_model::solver::SolverKind;
use serde::Serialize;

#[derive(Serialize)]
pub(super) struct Health {
    status: &'static str,
}

pub(super) async fn healthz() -> Json<Health> {
    Json(Health { status: "ok" })
}

#[derive(Serialize)]
#[serde(rename_all = "snake_case")]
pub(super) enum ReadyState {
    Ready,
    Degraded,
}

#[derive(Serialize)]
pub(super) struct Readiness {
    status: ReadyState,
    scenarios: usize,
    /// What the node works without for now (empty when ready).
    degraded: Vec<DegradedView>,
}

#[derive(Serialize)]
pub(super) struct DegradedView {
    component: Component,
    /// The problem code a request that needs the component answers with.
    code: &'static str,
    reason: String,
}

pub(super) async fn readyz(State(state): State<App>) -> Result<Json<Readiness>, ApiError> {
    if !state.is_ready() {
        return Err(ApiError::not_ready());
    }
    let degraded: Vec<DegradedView> = state
        .degradations()
        .into_iter()
        .map(|d| DegradedView {
            component: d.component,
            code: match d.component {
                Component::SharedStore => "store_unavailable",
                Component::DataDir => "data_dir_unwritable",
            },
            reason: d.reason,
        })
        .collect();
    Ok(Json(Readiness {
        status: if degraded.is_empty() {
            ReadyState::Ready
        } else {
            ReadyState::Degraded
        },
        scenarios: state.registry().len(),
        degraded,
    }))
}

#[derive(Serialize)]
pub(super) struct Version {
    name: &'static str,
    version: &'static str,
    sdr_sca_available: bool,
}

pub(super) async fn version() -> Json<Version> {
    Json(Version {
        name: env!("CARGO_PKG_NAME"),
        version: env!("CARGO_PKG_VERSION"),
        sdr_sca_available: SolverKind::SdrSca.is_available(),
    })
}

pub(super) async fn metrics_text(State(state): State<App>) -> Response {
    state.cache().record_size();
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.render_metrics(),
    )
        .into_response()
}
