//! The path use case, one function per step for `irs-planner plan` and `POST /v1/paths`: the
//! phase options checked once ([`phase_options`]), the planner's answer with its phases written
//! as asked ([`write_phases`]), and the optional Monte Carlo check of what is sent ([`check`]).
//! Finding the map and running the work (a progress bar, a query pool) stay with each front
//! door.

use crate::phase_text::{PhaseFormat, PhasePrecision, SurfacePhases};
use irs_model::input::FieldError;
use irs_model::montecarlo::{self, MonteCarloReport};
use irs_model::planner::{PathAnswer, Threshold, route_graph};
use irs_model::radiomap::{Cancelled, Progress, RadioMap, SurfaceRadians, Unit};
use irs_model::scenario::Scenario;

/// A path answer with its optional Monte Carlo check: the body of `irs-planner plan` and of
/// `POST /v1/paths`, written by [`CheckedPath::to_json`].
#[derive(Debug, Clone)]
pub struct CheckedPath {
    /// The planner's answer, phases written as asked; its fields are the body's.
    pub path: PathAnswer<SurfacePhases>,
    /// The Monte Carlo check of the phases as sent (docs/model.md §8), when asked for.
    pub monte_carlo: Option<MonteCarloReport>,
}

/// A path along the scenario's route graph (`path_shape` `route_graph`): its edges scored on
/// `map` with `values` (the map's values in `unit`), then the route from the node nearest
/// `start` to the node nearest `goal`. Errors name `path_shape` when the scenario has no
/// route graph and `tolerance_m` when one is given (the ends are the nearest nodes).
#[allow(clippy::too_many_arguments)]
pub fn plan_on_route_graph(
    scenario: &Scenario,
    map: &RadioMap,
    (unit, values): (Unit, &[f64]),
    tolerance_m: f64,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
) -> Result<PathAnswer, FieldError> {
    let graph = scenario.route_graph.as_deref().ok_or_else(|| {
        FieldError::new(
            "path_shape",
            "the map's scenario has no route graph: attach one as the scenario's route_graph",
        )
    })?;
    if tolerance_m > 0.0 {
        return Err(FieldError::new(
            "tolerance_m",
            "a route_graph path runs between the nodes nearest start and goal; give no tolerance",
        ));
    }
    let scores = route_graph::score_edges(map, values, graph);
    route_graph::plan_on_graph(
        map,
        (unit, values),
        graph,
        &scores,
        start,
        goal,
        threshold,
        scenario.mru.v_max_mps,
    )
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

/// Every waypoint's IRS phases written as `format` asks, radians rounded to `precision`, each
/// waypoint reproducible from what is written (docs/model.md §6). A rate map's codes, and its
/// phases in full, are those its split and value were worked out at; phases rounded to fewer
/// decimals are not, so there the waypoint's power split (for the cell's decoding order) and
/// value are worked out again at the phases as written. Where those serve not every SRU, or
/// give a value below the path's threshold, the waypoint's phases are written in full instead.
pub fn write_phases(
    scenario: &Scenario,
    map: &RadioMap,
    path: PathAnswer,
    format: PhaseFormat,
    precision: PhasePrecision,
) -> PathAnswer<SurfacePhases> {
    let rounded = format == PhaseFormat::Radians && precision.decimals().is_some();
    let Some(evaluator) = map.rate_evaluator(scenario).filter(|_| rounded) else {
        return format_phases(path, format, precision);
    };
    let full: Vec<SurfaceRadians> = path
        .waypoints
        .iter()
        .map(|w| w.config.phases.clone())
        .collect();
    let mut written = format_phases(path, format, precision);
    // Waypoint values are in the query's unit: a rate map's are rates, or throughputs.
    let scale = match written.unit {
        Unit::Mbps => map.links[0].bandwidth_mhz.unwrap_or(f64::NAN),
        _ => 1.0,
    };
    let threshold = written.threshold;
    for (waypoint, full) in written.waypoints.iter_mut().zip(full) {
        let cell = map.grid.index(waypoint.i, waypoint.j);
        let theta = waypoint.config.phases.radians().concat();
        match evaluator
            .split(cell, &theta)
            .filter(|split| threshold.is_none_or(|t| split.mru_rate * scale >= t))
        {
            Some(split) => {
                waypoint.value = split.mru_rate * scale;
                waypoint.config.power_w = Some(split.power_w);
            }
            None => waypoint.config.phases = SurfacePhases::Radians(full),
        }
    }
    written
}

/// Every waypoint's IRS phases written as `format` asks, radians rounded to `precision`.
pub(crate) fn format_phases(
    path: PathAnswer,
    format: PhaseFormat,
    precision: PhasePrecision,
) -> PathAnswer<SurfacePhases> {
    path.map_phases(|radians| {
        let phases = SurfacePhases::Radians(radians);
        match (format, precision.decimals()) {
            (PhaseFormat::Codes, _) => phases.to_codes(),
            (PhaseFormat::Radians, None) => phases,
            (PhaseFormat::Radians, Some(decimals)) => phases.into_decimals(decimals),
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::ScenarioDocument;
    use irs_model::planner::{self, PathOptions, Threshold};
    use irs_model::radiomap::{CellSolutions, MapKey};
    use irs_model::rate::Access;

    /// The paper's multi-user floor at 1 m with a second SRU.
    fn two_srus() -> Scenario {
        let mut doc: serde_json::Value =
            serde_json::from_str(include_str!("../../../scenarios/paper-multi-user.json")).unwrap();
        doc["grid"]["resolution_m"] = 1.0.into();
        doc["srus"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({"position": [-6.0, 7.0, 1.3], "min_rate_bps_hz": 0.5}));
        Scenario::from_value(doc).unwrap()
    }

    /// At every precision and in codes, each waypoint of a rate-map path re-evaluated from its
    /// own phases as written, powers and the cell's decoding order gives every SRU its r̄ and
    /// the MRU the waypoint's value (to 1e-9), at or above the path's threshold: at the largest
    /// feasible threshold, where coarse rounding must fall back to full phases, and below it,
    /// where the split is worked out again at the rounded phases.
    #[test]
    fn rate_waypoints_reproduce_themselves_at_every_precision() {
        let s = two_srus();
        let (mut recomputed, mut kept_full) = (0, 0);
        for access in [Access::Oma, Access::Noma] {
            let key =
                MapKey::rate("test", &s, irs_model::phases::PhaseMode::Continuous, access).unwrap();
            let map = crate::map::build(&s, &key, &Progress::default()).unwrap();
            let CellSolutions::Rate(cells) = &map.cells else {
                panic!("a rate map")
            };
            let evaluator = map.rate_evaluator(&s).unwrap();
            let model = evaluator.rate_model();
            let plan = |threshold| {
                let path = planner::plan(
                    &map,
                    Unit::BpsHz,
                    PathOptions::default(),
                    [-8.0, -8.0],
                    [8.0, 8.0],
                    threshold,
                    1.0,
                )
                .unwrap();
                assert!(path.feasible, "{:?}", path.reason);
                path
            };
            let widest = plan(Threshold::Max).threshold.unwrap();
            for threshold in [Threshold::Max, Threshold::Value(widest - 0.3)] {
                let path = plan(threshold);
                let gamma = path.threshold.unwrap();
                let written = [
                    (PhaseFormat::Codes, PhasePrecision::default()),
                    (PhaseFormat::Radians, "full".parse().unwrap()),
                    (PhaseFormat::Radians, "1e-6".parse().unwrap()),
                    (PhaseFormat::Radians, "1e-4".parse().unwrap()),
                    (PhaseFormat::Radians, "1e-3".parse().unwrap()),
                    (PhaseFormat::Radians, "1e-2".parse().unwrap()),
                ];
                for (format, precision) in written {
                    let answer = write_phases(&s, &map, path.clone(), format, precision);
                    for (w, before) in answer.waypoints.iter().zip(&path.waypoints) {
                        let cell = map.grid.index(w.i, w.j);
                        let theta = w.config.phases.radians().concat();
                        let power = w.config.power_w.as_ref().unwrap();
                        let gains = evaluator.gains(cell, &theta);
                        let rates = model.rates(&gains, power, cells.order(cell));
                        let at =
                            format!("{access:?} γ {gamma} {format:?} {precision:?} cell {cell}");
                        assert!(
                            (rates[0] - w.value).abs() < 1e-9,
                            "{at}: {} vs {}",
                            rates[0],
                            w.value
                        );
                        assert!(w.value >= gamma, "{at}: {} < γ", w.value);
                        for (&r, &target) in rates.iter().zip(model.targets()).skip(1) {
                            assert!(r >= target - 1e-9, "{at}: an SRU gets {r} < {target}");
                        }
                        if matches!(w.config.phases, SurfacePhases::Decimals(_)) {
                            recomputed += usize::from(w.value != before.value);
                        } else if format == PhaseFormat::Radians && precision.decimals().is_some() {
                            kept_full += 1;
                        }
                    }
                }
            }
        }
        assert!(
            recomputed > 0 && kept_full > 0,
            "{recomputed} recomputed, {kept_full} kept in full"
        );
    }
}
