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

/// The frame a path's positions are given in, as a ROS message names it (`header.frame_id`):
/// a tf2 frame id of letters, digits, `_` and `/`, not starting with `/` (tf2 refuses a leading
/// slash), at most [`FrameId::MAX_CHARS`] characters. `map` by default (REP 105).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct FrameId(String);

impl FrameId {
    /// Longest frame id accepted.
    pub const MAX_CHARS: usize = 128;

    /// A frame id as a request or a flag gives it; the reason when it is not one.
    pub fn parse(text: &str) -> Result<FrameId, String> {
        if text.is_empty() || text.len() > Self::MAX_CHARS {
            return Err(format!(
                "a frame id has 1 to {} characters",
                Self::MAX_CHARS
            ));
        }
        if text.starts_with('/') {
            return Err("a frame id does not start with / (tf2 refuses it)".into());
        }
        if let Some(bad) = text
            .chars()
            .find(|c| !(c.is_ascii_alphanumeric() || *c == '_' || *c == '/'))
        {
            return Err(format!(
                "{bad:?} is not allowed in a frame id (letters, digits, _ and / only)"
            ));
        }
        Ok(FrameId(text.to_string()))
    }

    /// The frame id as text.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

impl Default for FrameId {
    fn default() -> Self {
        FrameId(irs_model::planner::DEFAULT_FRAME.to_string())
    }
}

impl<'de> serde::Deserialize<'de> for FrameId {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        FrameId::parse(&text).map_err(serde::de::Error::custom)
    }
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
