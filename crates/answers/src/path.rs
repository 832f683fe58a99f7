//! The path use case, one function per step for `irs-planner plan` and `POST /v1/paths`: the
//! phase options checked once ([`phase_options`]), the planner's answer with its phases written
//! as asked ([`write_phases`]), and the optional Monte Carlo check of what is sent ([`check`]).
//! Finding the map and running the work (a progress bar, a query pool) stay with each front
//! door.

use crate::phase_text::{PhaseFormat, PhasePrecision, SurfacePhases};
use irs_model::input::FieldError;
use irs_model::montecarlo::{self, MonteCarloReport};
use irs_model::planner::PathAnswer;
use irs_model::radiomap::{Cancelled, Progress, RadioMap};
use irs_model::scenario::Scenario;
use serde::Serialize;

/// A path answer with its optional Monte Carlo check: the body of `irs-planner plan` and of
/// `POST /v1/paths`.
#[derive(Debug, Clone, Serialize)]
pub struct CheckedPath {
    /// The planner's answer, phases written as asked; flattened into the body.
    #[serde(flatten)]
    pub path: PathAnswer<SurfacePhases>,
    /// The Monte Carlo check of the phases as sent (docs/model.md §8), when asked for.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub monte_carlo: Option<MonteCarloReport>,
}

/// The phase format and precision of a path answer, defaults applied. A precision applies to
/// radians only: with codes it is refused (field `phase_precision`) rather than ignored.
pub fn phase_options(
    format: Option<PhaseFormat>,
    precision: Option<PhasePrecision>,
) -> Result<(PhaseFormat, PhasePrecision), FieldError> {
    let format = format.unwrap_or_default();
    if format == PhaseFormat::Codes && precision.is_some() {
        return Err(FieldError::new(
            "phase_precision",
            "applies to phase_format radians only (codes are steps of 2π/65536)",
        ));
    }
    Ok((format, precision.unwrap_or_default()))
}

/// Every waypoint's IRS phases written as `format` asks, radians rounded to `precision`.
pub fn write_phases(
    path: PathAnswer,
    format: PhaseFormat,
    precision: PhasePrecision,
) -> PathAnswer<SurfacePhases> {
    path.map_phases(|radians| {
        let phases = SurfacePhases::Radians(radians);
        match (format, precision.decimals()) {
            (PhaseFormat::Codes, _) => phases.to_codes(),
            (PhaseFormat::Radians, None) => phases,
            (PhaseFormat::Radians, Some(decimals)) => phases.to_decimals(decimals),
        }
    })
}

/// The Monte Carlo check (paper Fig. 10) of a written path: it evaluates the phases as sent
/// (decimals read back, codes decoded), not the unrounded ones.
pub fn check(
    scenario: &Scenario,
    map: &RadioMap,
    path: &PathAnswer<SurfacePhases>,
    draws: usize,
    seed: u64,
    progress: &Progress,
) -> Result<MonteCarloReport, Cancelled> {
    let sent = path.clone().map_phases(|phases| phases.radians());
    montecarlo::check_path(scenario, map, &sent, draws, seed, progress)
}
