//! Communication-aware paths over a radio map (docs/model.md §6, paper Section II-D): path and
//! sweep queries and the answers they return. The searches themselves live in [`graph`].

mod bottleneck;
pub mod graph;
mod queue;

pub use bottleneck::Bottlenecks;
pub use graph::{CellGraph, Infeasible, Path};

use crate::input::{FieldError, parse_finite};
use crate::radiomap::{Cancelled, CellConfig, Progress, RadioMap, WorkError};
use crate::scenario::Grid;
use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The QoS threshold of a path query: a value in the map's unit, or the largest feasible one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    Value(f64),
    Max,
}

impl Serialize for Threshold {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Threshold::Value(v) => s.serialize_f64(*v),
            Threshold::Max => s.serialize_str("max"),
        }
    }
}

impl FromStr for Threshold {
    type Err = String;
    /// `"max"` or a finite number, as in `?threshold=` and `--threshold`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "max" => Ok(Threshold::Max),
            number => parse_finite(number)
                .map(Threshold::Value)
                .map_err(|e| format!("expected a number or \"max\": {e}")),
        }
    }
}

impl<'de> Deserialize<'de> for Threshold {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match serde_json::Value::deserialize(d)? {
            serde_json::Value::String(s) if s == "max" => Ok(Threshold::Max),
            serde_json::Value::Number(n) => n
                .as_f64()
                .filter(|v| v.is_finite())
                .map(Threshold::Value)
                .ok_or_else(|| serde::de::Error::custom("threshold must be a finite number")),
            other => Err(serde::de::Error::custom(format!(
                "expected a number or \"max\", got {other}"
            ))),
        }
    }
}

/// Where a requested point landed on the grid.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Endpoint {
    pub requested: [f64; 2],
    pub x: f64,
    pub y: f64,
    pub i: usize,
    pub j: usize,
    /// True when the requested point was not itself a cell centre.
    pub snapped: bool,
}

/// One waypoint of a path and the configuration to apply there.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Waypoint {
    pub x: f64,
    pub y: f64,
    pub i: usize,
    pub j: usize,
    /// The map's value at this cell.
    pub value: f64,
    #[serde(flatten)]
    pub config: CellConfig,
}

/// Where a path changes its serving AP (several APs): between waypoint `waypoint − 1` and
/// `waypoint`, at (x, y) — the first waypoint served by `to`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Handover {
    pub waypoint: usize,
    pub x: f64,
    pub y: f64,
    pub from: usize,
    pub to: usize,
}

/// The answer to a path query; the same body from the CLI and the API.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PathAnswer {
    pub map_id: String,
    pub unit: &'static str,
    /// The threshold applied (for `"max"`, the largest feasible one).
    pub threshold: Option<f64>,
    pub feasible: bool,
    pub reason: Option<Infeasible>,
    pub distance_m: Option<f64>,
    pub travel_time_s: Option<f64>,
    /// The largest threshold for which any path joins start and goal.
    pub max_feasible_threshold: Option<f64>,
    pub start: Endpoint,
    pub goal: Endpoint,
    pub waypoints: Vec<Waypoint>,
    /// The handovers along the path, in order (empty with one AP).
    pub handovers: Vec<Handover>,
}

/// One point of a threshold sweep (paper Figs. 7 and 9).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepPoint {
    pub threshold: f64,
    pub feasible: bool,
    pub reason: Option<Infeasible>,
    pub distance_m: Option<f64>,
    pub travel_time_s: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SweepAnswer {
    pub map_id: String,
    pub unit: &'static str,
    pub max_feasible_threshold: Option<f64>,
    pub start: Endpoint,
    pub goal: Endpoint,
    pub points: Vec<SweepPoint>,
}

fn endpoint(grid: &Grid, field: &str, p: [f64; 2]) -> Result<(usize, Endpoint), FieldError> {
    let (i, j) = grid.snap(p[0], p[1]).ok_or_else(|| {
        FieldError::new(field, format!("({}, {}) lies outside the room", p[0], p[1]))
    })?;
    let [x, y] = grid.centre(i, j);
    let snapped = (x - p[0]).abs() > 1e-9 || (y - p[1]).abs() > 1e-9;
    Ok((
        grid.index(i, j),
        Endpoint {
            requested: p,
            x,
            y,
            i,
            j,
            snapped,
        },
    ))
}

fn graph(map: &RadioMap) -> CellGraph<'_> {
    CellGraph {
        grid: &map.grid,
        values: &map.values,
        occupied: &map.occupied,
    }
}

/// Builds a map's [`Bottlenecks`] index, for [`plan_indexed`] and [`sweep`].
pub fn bottlenecks(map: &RadioMap) -> Bottlenecks {
    Bottlenecks::new(&graph(map))
}

/// Plans the shortest feasible path on a map (start/goal snapped to the nearest cell centre),
/// finding the widest-path threshold by a search: the cheaper way for one query on a map.
pub fn plan(
    map: &RadioMap,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    plan_with(map, start, goal, threshold, v_max_mps, |graph, s, g| {
        graph.widest_path_threshold(s, g)
    })
}

/// [`plan`] with the widest-path threshold read from the map's [`Bottlenecks`] index: the
/// cheaper way for a map that answers many queries (the service keeps the index with the map).
pub fn plan_indexed(
    map: &RadioMap,
    index: &Bottlenecks,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
) -> Result<PathAnswer, FieldError> {
    plan_with(map, start, goal, threshold, v_max_mps, |_, s, g| {
        index.widest_path_threshold(&map.values, s, g)
    })
}

fn plan_with(
    map: &RadioMap,
    start: [f64; 2],
    goal: [f64; 2],
    threshold: Threshold,
    v_max_mps: f64,
    widest_path_threshold: impl FnOnce(&CellGraph, usize, usize) -> Option<f64>,
) -> Result<PathAnswer, FieldError> {
    let (s, start) = endpoint(&map.grid, "start", start)?;
    let (g, goal) = endpoint(&map.grid, "goal", goal)?;
    let graph = graph(map);
    let widest = widest_path_threshold(&graph, s, g);
    let applied = match threshold {
        Threshold::Value(v) => Some(v),
        Threshold::Max => widest,
    };
    let result = match applied {
        Some(t) => graph.shortest_path(s, g, t),
        None => Err(if map.occupied[s] {
            Infeasible::StartOccupied
        } else if map.occupied[g] {
            Infeasible::GoalOccupied
        } else {
            Infeasible::Disconnected
        }),
    };
    let mut answer = PathAnswer {
        map_id: map.id.clone(),
        unit: map.key.unit(),
        threshold: applied,
        feasible: result.is_ok(),
        reason: result.as_ref().err().copied(),
        distance_m: None,
        travel_time_s: None,
        max_feasible_threshold: widest,
        start,
        goal,
        waypoints: Vec::new(),
        handovers: Vec::new(),
    };
    if let Ok(path) = result {
        answer.distance_m = Some(path.distance_m);
        answer.travel_time_s = Some(path.distance_m / v_max_mps);
        answer.waypoints = path
            .cells
            .iter()
            .map(|&c| {
                let (i, j) = map.grid.cell_of(c);
                let [x, y] = map.grid.centre(i, j);
                Waypoint {
                    x,
                    y,
                    i,
                    j,
                    value: map.values[c],
                    config: map.cell_config(c),
                }
            })
            .collect();
        answer.handovers = answer
            .waypoints
            .windows(2)
            .enumerate()
            .filter(|(_, pair)| pair[0].config.ap != pair[1].config.ap)
            .map(|(k, pair)| Handover {
                waypoint: k + 1,
                x: pair[1].x,
                y: pair[1].y,
                from: pair[0].config.ap,
                to: pair[1].config.ap,
            })
            .collect();
    }
    Ok(answer)
}

/// How finely a path answer's IRS phases are written. A phase written with 17 significant
/// digits is ≈ 20 bytes of JSON and most of a path answer (the paper map's path: 49.6 kB in
/// full, 21.1 kB at the default); no IRS resolves anything near that: 2-bit to 8-bit surfaces
/// have steps of 1.57 to 0.025 rad, and a phase error ε costs at most a factor cos ε of a
/// reflected term's amplitude, 1 − 1.25·10⁻⁹ (10⁻⁸ dB) at the default ε ≤ 5·10⁻⁵ rad. A rate
/// map's phases are already stored to 2π/2¹⁶ (`phases::encode_phase`), so for them `1e-6` and
/// `full` write the stored phases. Rounded phases are written by
/// [`SurfacePhases::to_decimals`], straight from θ to digits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum PhasePrecision {
    /// Rounded to 2 decimals (error ≤ 0.005 rad).
    #[serde(rename = "1e-2")]
    Centi,
    /// Rounded to 3 decimals (error ≤ 5·10⁻⁴ rad).
    #[serde(rename = "1e-3")]
    Milli,
    /// Rounded to 4 decimals (error ≤ 5·10⁻⁵ rad), the default.
    #[default]
    #[serde(rename = "1e-4")]
    TenthMilli,
    /// Rounded to 6 decimals (error ≤ 5·10⁻⁷ rad).
    #[serde(rename = "1e-6")]
    Micro,
    /// Every bit of the f64 (the shortest decimal that reads back to the same number).
    #[serde(rename = "full")]
    Full,
}

impl PhasePrecision {
    /// Decimals kept, `None` for full precision.
    fn decimals(self) -> Option<u32> {
        match self {
            PhasePrecision::Centi => Some(2),
            PhasePrecision::Milli => Some(3),
            PhasePrecision::TenthMilli => Some(4),
            PhasePrecision::Micro => Some(6),
            PhasePrecision::Full => None,
        }
    }
}

impl FromStr for PhasePrecision {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::input::parse_name(s)
    }
}

/// How a path answer writes its IRS phases: decimals in radians (`irs_phases_rad`, rounded to
/// a [`PhasePrecision`]), or 16-bit codes in base64 (`irs_phase_codes`,
/// [`SurfacePhases::Codes`]): within π/2¹⁶ ≈ 4.8·10⁻⁵ rad, as fine as the default 10⁻⁴ rad,
/// in 2.7 characters a phase instead of 6–7, and directly the levels a b-bit surface
/// controller takes (c >> (16 − b)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PhaseFormat {
    #[default]
    Radians,
    Codes,
}

impl FromStr for PhaseFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::input::parse_name(s)
    }
}

impl PathAnswer {
    /// Writes every waypoint's IRS phases as `format` asks, radians rounded to `precision`.
    pub fn write_phases(&mut self, format: PhaseFormat, precision: PhasePrecision) {
        for waypoint in &mut self.waypoints {
            let phases = &mut waypoint.config.phases;
            match (format, precision.decimals()) {
                (PhaseFormat::Codes, _) => *phases = phases.to_codes(),
                (PhaseFormat::Radians, None) => {}
                (PhaseFormat::Radians, Some(decimals)) => *phases = phases.to_decimals(decimals),
            }
        }
    }
}

/// Distance versus threshold for a list of thresholds, in one request, on a map whose
/// [`Bottlenecks`] index is at hand (a sweep is a query of the service, which keeps it).
/// `progress` counts the thresholds done; cancelling it stops the sweep before the next
/// threshold.
pub fn sweep(
    map: &RadioMap,
    index: &Bottlenecks,
    start: [f64; 2],
    goal: [f64; 2],
    thresholds: &[f64],
    v_max_mps: f64,
    progress: &Progress,
) -> Result<SweepAnswer, WorkError> {
    let (s, start) = endpoint(&map.grid, "start", start)?;
    let (g, goal) = endpoint(&map.grid, "goal", goal)?;
    let graph = graph(map);
    progress.start(thresholds.len());
    let points = thresholds
        .iter()
        .map(|&t| {
            if progress.is_cancelled() {
                return Err(Cancelled);
            }
            let r = graph.shortest_path(s, g, t);
            progress.advance(1);
            Ok(SweepPoint {
                threshold: t,
                feasible: r.is_ok(),
                reason: r.as_ref().err().copied(),
                distance_m: r.as_ref().ok().map(|p| p.distance_m),
                travel_time_s: r.as_ref().ok().map(|p| p.distance_m / v_max_mps),
            })
        })
        .collect::<Result<_, Cancelled>>()?;
    Ok(SweepAnswer {
        map_id: map.id.clone(),
        unit: map.key.unit(),
        max_feasible_threshold: index.widest_path_threshold(&map.values, s, g),
        start,
        goal,
        points,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radiomap::SurfacePhases;

    /// Each precision writes its number of decimals (the writer itself is tested in
    /// radiomap::phase_text); `full` keeps every bit; codes are codes.
    #[test]
    fn write_phases_applies_the_precision_asked_for() {
        let theta = 4.71238898038469;
        let answer = |format, precision| {
            let end = Endpoint {
                requested: [0.0, 0.0],
                x: 0.0,
                y: 0.0,
                i: 0,
                j: 0,
                snapped: false,
            };
            let mut path = PathAnswer {
                map_id: String::new(),
                unit: "dB",
                threshold: None,
                feasible: true,
                reason: None,
                distance_m: Some(0.0),
                travel_time_s: Some(0.0),
                max_feasible_threshold: None,
                start: end.clone(),
                goal: end,
                waypoints: vec![Waypoint {
                    x: 0.0,
                    y: 0.0,
                    i: 0,
                    j: 0,
                    value: 0.0,
                    config: CellConfig {
                        ap: 0,
                        phases: SurfacePhases::Radians(vec![vec![theta, 0.5]]),
                        power_w: None,
                        decoding_order: None,
                    },
                }],
                handovers: Vec::new(),
            };
            path.write_phases(format, precision);
            serde_json::to_value(&path.waypoints[0].config).unwrap()
        };
        assert_eq!(PhasePrecision::default(), PhasePrecision::TenthMilli);
        for (precision, written) in [
            ("1e-2", vec![4.71, 0.5]),
            ("1e-3", vec![4.712, 0.5]),
            ("1e-4", vec![4.7124, 0.5]),
            ("1e-6", vec![4.712389, 0.5]),
            ("full", vec![theta, 0.5]),
        ] {
            let precision: PhasePrecision = precision.parse().unwrap();
            let config = answer(PhaseFormat::Radians, precision);
            assert_eq!(config["irs_phases_rad"], serde_json::json!([written]));
        }
        let codes = answer(PhaseFormat::Codes, PhasePrecision::default());
        assert!(codes["irs_phase_codes"][0].is_string());
        assert_eq!("1e-6".parse::<PhasePrecision>(), Ok(PhasePrecision::Micro));
        assert!("1e-5".parse::<PhasePrecision>().is_err());
    }

    #[test]
    fn thresholds_parse_as_in_json() {
        assert_eq!("max".parse::<Threshold>(), Ok(Threshold::Max));
        assert_eq!("-63.5".parse::<Threshold>(), Ok(Threshold::Value(-63.5)));
        assert!("NaN".parse::<Threshold>().is_err());
        assert!("maximum".parse::<Threshold>().is_err());
    }
}
