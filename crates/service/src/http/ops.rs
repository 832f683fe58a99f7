//! The operations endpoints: `/healthz` (the process answers), `/readyz` (ready to serve: in a
//! cluster the shared store reachable, with `--data-dir` the directory writable), `/version` and `/metrics` (Prometheus text).

use super::problem::ApiError;
use crate::app::App;
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
pub(super) struct Readiness {
    status: &'static str,
    scenarios: usize,
}

pub(super) async fn readyz(State(state): State<App>) -> Result<Json<Readiness>, ApiError> {
    if !state.is_ready() {
        return Err(ApiError::not_ready());
    }
    state.store_available()?;
    if let Some(reason) = state.data_dir().and_then(|dir| dir.unwritable()) {
        return Err(ApiError::data_dir_unwritable(reason));
    }
    Ok(Json(Readiness {
        status: "ready",
        scenarios: state.registry().len(),
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
