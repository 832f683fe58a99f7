//! What a path query asks beyond its ends: the QoS threshold (a value or "max"), the route's
//! shape and the tolerance at its ends.

use crate::input::{Scalar, parse_finite};
use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The QoS threshold of a path query: a value in the query's unit, or the largest feasible one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Threshold {
    /// γ in the query's [`Unit`] (by default the map's: dB on gain maps, bit/s/Hz on rate maps).
    Value(f64),
    /// The largest γ for which any path joins start and goal (the widest-path value, §6).
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
        match crate::input::deserialize_scalar(d)? {
            Scalar::Text(s) if s == "max" => Ok(Threshold::Max),
            Scalar::Number(n, _) if n.is_finite() => Ok(Threshold::Value(n)),
            Scalar::Number(..) => Err(serde::de::Error::custom(
                "threshold must be a finite number",
            )),
            Scalar::Text(s) => Err(serde::de::Error::custom(format!(
                "expected a number or \"max\", got {s:?}"
            ))),
            Scalar::Other(other) => Err(serde::de::Error::custom(format!(
                "expected a number or \"max\", got {other}"
            ))),
        }
    }
}

/// The shape of a path's route (docs/model.md §6).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PathShape {
    /// 8-connected steps between cell centres (the paper's, and the default).
    #[default]
    Grid,
    /// Straight segments at any angle between cell centres, each driven only where every cell
    /// it crosses is free and meets the threshold; never longer than the grid path.
    AnyAngle,
    /// Along the scenario's route graph, from the node nearest the start to the node nearest
    /// the goal, over edges whose every cell meets the threshold.
    RouteGraph,
}

impl FromStr for PathShape {
    type Err = String;
    fn from_str(s: &str) -> Result<PathShape, String> {
        match s {
            "grid" => Ok(PathShape::Grid),
            "any_angle" | "any-angle" => Ok(PathShape::AnyAngle),
            "route_graph" | "route-graph" => Ok(PathShape::RouteGraph),
            other => Err(format!(
                "expected grid, any_angle or route_graph, got {other:?}"
            )),
        }
    }
}

/// Largest `tolerance_m` accepted (m): far beyond a planner's usual goal tolerance, small
/// enough that the search around an end stays a window of the map.
pub const MAX_TOLERANCE_M: f64 = 50.0;

/// How a path query is answered beyond its ends and threshold.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PathOptions {
    /// The route's shape.
    pub shape: PathShape,
    /// How far (m) a start or goal whose own cell is occupied or below the threshold may move
    /// to the nearest cell that is not (Nav2's planner tolerance); 0, the default, moves none.
    pub tolerance_m: f64,
}

impl PathOptions {
    /// An any-angle route, no tolerance.
    pub fn any_angle() -> PathOptions {
        PathOptions {
            shape: PathShape::AnyAngle,
            ..PathOptions::default()
        }
    }
}
