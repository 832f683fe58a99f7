//! Planned paths as VDA 5050 orders, checked against the rules of the specification's §6.1.1
//! that its JSON schema cannot state (the schema itself is checked in CI by
//! `tests/exports/vda5050_check.py`), and the released base against its definition evaluated on
//! the map's own cells; zone sets against the cells they must cover.

mod common;

use common::gain_map;
use irs_answers::scenario::ScenarioDocument;
use irs_answers::vda5050::{self, Header, OrderParams, ZoneParams};
use irs_model::phases::PhaseMode;
use irs_model::planner::{self, PathAnswer, PathOptions, PathShape, Threshold};
use irs_model::radiomap::RadioMap;
use irs_model::scenario::Scenario;
use proptest::prelude::*;
use serde_json::Value;
use std::sync::OnceLock;
use std::time::{Duration, SystemTime};

/// The paper's floor at 0.25 m (81 × 81 cells) and its gain map.
fn floor() -> &'static (Scenario, RadioMap) {
    static FLOOR: OnceLock<(Scenario, RadioMap)> = OnceLock::new();
    FLOOR.get_or_init(|| {
        let s = Scenario::builtin_with("paper-single-user", |v| {
            v["grid"]["resolution_m"] = 0.25.into();
        })
        .unwrap()
        .unwrap();
        let map = gain_map(&s, PhaseMode::Continuous);
        (s, map)
    })
}

fn plan(shape: PathShape, start: [f64; 2], goal: [f64; 2], threshold: Threshold) -> PathAnswer {
    let (s, map) = floor();
    let options = PathOptions {
        shape,
        ..PathOptions::default()
    };
    planner::plan(
        map,
        map.native_unit(),
        options,
        start,
        goal,
        threshold,
        s.mru.v_max_mps,
    )
    .unwrap()
}

fn order(path: &PathAnswer, margin: f64) -> Value {
    let params = OrderParams {
        release_margin: margin,
        ..OrderParams::default()
    };
    let at = SystemTime::UNIX_EPOCH + Duration::from_millis(1_764_979_200_123);
    serde_json::to_value(vda5050::order(path, &params, at).unwrap()).unwrap()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// Everything §6.1.1 and §7.3 require of an order's graph that the schema does not: edges one
/// fewer than nodes, sequence ids 0, 1, 2, … alternating node and edge, the first node
/// released, the base a prefix of the sequence (an edge released only between released
/// nodes), clamped degree-1 trajectories joining the nodes, lengths that add up to the path's.
fn check_rules(order: &Value, path: &PathAnswer) -> Result<(), TestCaseError> {
    let nodes = order["nodes"].as_array().unwrap();
    let edges = order["edges"].as_array().unwrap();
    prop_assert!(!nodes.is_empty());
    prop_assert_eq!(edges.len(), nodes.len() - 1);
    prop_assert_eq!(nodes.len(), path.vertices.len());
    prop_assert!(
        nodes[0]["released"].as_bool().unwrap(),
        "the first node is released"
    );
    let mut sequence = Vec::new();
    for (k, node) in nodes.iter().enumerate() {
        prop_assert_eq!(node["sequenceId"].as_u64().unwrap(), 2 * k as u64);
        let w = &path.waypoints[path.vertices[k]];
        prop_assert_eq!(f(&node["nodePosition"]["x"]), w.x);
        prop_assert_eq!(f(&node["nodePosition"]["y"]), w.y);
        prop_assert_eq!(&node["nodePosition"]["mapId"], "map");
        prop_assert_eq!(node["actions"].as_array().unwrap().len(), 0);
        sequence.push(node["released"].as_bool().unwrap());
        if let Some(edge) = edges.get(k) {
            prop_assert_eq!(edge["sequenceId"].as_u64().unwrap(), 2 * k as u64 + 1);
            sequence.push(edge["released"].as_bool().unwrap());
        }
    }
    // After an unreleased element, no released one follows.
    let base = sequence.iter().take_while(|r| **r).count();
    prop_assert!(
        sequence[base..].iter().all(|r| !r),
        "released after the horizon began"
    );
    prop_assert!(base % 2 == 1, "the base ends on a node, not an edge");
    let mut total = 0.0;
    for (k, edge) in edges.iter().enumerate() {
        let t = &edge["trajectory"];
        let degree = t["degree"].as_u64().unwrap() as usize;
        let knots: Vec<f64> = t["knotVector"].as_array().unwrap().iter().map(f).collect();
        let points = t["controlPoints"].as_array().unwrap();
        prop_assert_eq!(degree, 1);
        prop_assert!(points.len() > degree);
        prop_assert_eq!(knots.len(), points.len() + degree + 1);
        prop_assert!(
            knots.windows(2).all(|p| p[0] <= p[1]) && knots.iter().all(|k| (0.0..=1.0).contains(k))
        );
        prop_assert!(knots[..=degree].iter().all(|k| *k == 0.0), "clamped at 0");
        prop_assert!(
            knots[knots.len() - degree - 1..].iter().all(|k| *k == 1.0),
            "clamped at 1"
        );
        let (a, b) = (&nodes[k]["nodePosition"], &nodes[k + 1]["nodePosition"]);
        prop_assert_eq!(f(&points[0]["x"]), f(&a["x"]));
        prop_assert_eq!(f(&points[0]["y"]), f(&a["y"]));
        prop_assert_eq!(f(&points[1]["x"]), f(&b["x"]));
        prop_assert_eq!(f(&points[1]["y"]), f(&b["y"]));
        let length = f(&edge["length"]);
        prop_assert!(
            (length - (f(&b["x"]) - f(&a["x"])).hypot(f(&b["y"]) - f(&a["y"]))).abs() < 1e-12
        );
        total += length;
        prop_assert_eq!(edge["actions"].as_array().unwrap().len(), 0);
    }
    prop_assert!((total - path.distance_m.unwrap()).abs() < 1e-9 * total.max(1.0));
    Ok(())
}

/// The released base by its definition, on the map's values at the cells the waypoints name:
/// the last vertex from which every cell to the next vertex (the goal: its own) is at least
/// threshold + margin; the start when there is none.
fn last_released_by_definition(map: &RadioMap, path: &PathAnswer, margin: f64) -> usize {
    let floor = path.threshold.unwrap() + margin;
    let value = |w: usize| {
        let p = &path.waypoints[w];
        map.values[map.grid.index(p.i, p.j)]
    };
    let v = &path.vertices;
    (0..v.len())
        .filter(|&k| {
            let to = v.get(k + 1).copied().unwrap_or(v[k]);
            (v[k]..=to).all(|w| value(w) >= floor)
        })
        .max()
        .unwrap_or(0)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Random ends, thresholds (a value or max), shapes and margins: every order keeps the
    /// rules, its base ends where the definition says, and with no margin a feasible path is
    /// released whole (every cell of it meets the threshold).
    #[test]
    fn orders_keep_the_rules_and_release_as_defined(
        start in (-10.0..10.0f64, -10.0..10.0f64),
        goal in (-10.0..10.0f64, -10.0..10.0f64),
        threshold in prop_oneof![Just(None), (-90.0..-55.0f64).prop_map(Some)],
        any_angle in any::<bool>(),
        margin in prop_oneof![Just(0.0), 0.0..30.0f64],
    ) {
        let (_, map) = floor();
        let shape = if any_angle { PathShape::AnyAngle } else { PathShape::Grid };
        let threshold = threshold.map_or(Threshold::Max, Threshold::Value);
        let path = plan(shape, [start.0, start.1], [goal.0, goal.1], threshold);
        prop_assume!(path.feasible);
        let order = order(&path, margin);
        check_rules(&order, &path)?;
        let released = order["nodes"].as_array().unwrap().iter()
            .filter(|n| n["released"].as_bool().unwrap()).count();
        prop_assert_eq!(released - 1, last_released_by_definition(map, &path, margin));
        if margin == 0.0 {
            prop_assert_eq!(released, path.vertices.len(), "a feasible path is released whole");
        }
    }
}

/// A margin above every cell's value releases the start alone; the order id is stable for the
/// same query and differs for another; the timestamp is the specification's form.
#[test]
fn a_margin_too_high_releases_the_start_alone_and_ids_are_stable() {
    let path = plan(PathShape::Grid, [-8.0, -8.0], [8.0, 6.0], Threshold::Max);
    let tight = order(&path, 500.0);
    let released: Vec<bool> = tight["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n["released"].as_bool().unwrap())
        .collect();
    assert!(released.len() > 2);
    assert!(
        released[0] && released[1..].iter().all(|r| !r),
        "{released:?}"
    );
    assert_eq!(tight["timestamp"], "2025-12-06T00:00:00.123Z");
    assert_eq!(tight["version"], "3.0.0");
    assert_eq!(order(&path, 0.0)["orderId"], tight["orderId"]);
    let other = plan(PathShape::Grid, [-8.0, -8.0], [8.0, 5.0], Threshold::Max);
    assert_ne!(order(&other, 0.0)["orderId"], tight["orderId"]);
}

/// An infeasible path has nothing to order (the error names the threshold), and bad
/// parameters are refused by name.
#[test]
fn no_route_no_order_and_bad_parameters_are_named() {
    let none = plan(
        PathShape::Grid,
        [-8.0, -8.0],
        [8.0, 6.0],
        Threshold::Value(100.0),
    );
    assert!(!none.feasible);
    let e = vda5050::order(&none, &OrderParams::default(), SystemTime::now()).unwrap_err();
    assert_eq!(e.field, "threshold");
    let path = plan(PathShape::Grid, [-8.0, -8.0], [8.0, 6.0], Threshold::Max);
    for (params, field) in [
        (
            OrderParams {
                release_margin: f64::NAN,
                ..OrderParams::default()
            },
            "order.release_margin",
        ),
        (
            OrderParams {
                header: Header {
                    serial_number: "x".repeat(vda5050::MAX_TEXT_CHARS + 1),
                    ..Header::default()
                },
                ..OrderParams::default()
            },
            "order.serial_number",
        ),
    ] {
        let e = vda5050::order(&path, &params, SystemTime::now()).unwrap_err();
        assert_eq!(e.field, field);
    }
}

/// Whether `q` lies strictly inside the polygon of `vertices` (even-odd rule).
fn contains(vertices: &[Value], q: [f64; 2]) -> bool {
    let p: Vec<[f64; 2]> = vertices.iter().map(|v| [f(&v["x"]), f(&v["y"])]).collect();
    let mut inside = false;
    for k in 0..p.len() {
        let (a, b) = (p[k], p[(k + 1) % p.len()]);
        if (a[1] > q[1]) != (b[1] > q[1])
            && q[0] < a[0] + (q[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
        {
            inside = !inside;
        }
    }
    inside
}

/// Every free cell below the threshold lies in a BLOCKED zone, every free cell whose penalty
/// is at least k/L in a PENALTY zone of factor k/L (and none above its own level in a zone
/// that covers only such cells' band); zones are counterclockwise with unique ids.
#[test]
fn zone_sets_cover_the_cells_they_must() {
    let (_, map) = floor();
    // The median value: half the free floor blocked, the band above it penalised.
    let mut finite: Vec<f64> = map
        .values
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    finite.sort_by(f64::total_cmp);
    let (threshold, band, levels) = (finite[finite.len() / 2], 6.0, 4);
    let params = ZoneParams {
        penalty_band: Some(band),
        penalty_levels: Some(levels),
        ..ZoneParams::default()
    };
    let zones = vda5050::zone_set(
        map,
        map.native_unit(),
        threshold,
        &params,
        SystemTime::now(),
    )
    .unwrap();
    let (blocked, penalty) = zones.counts();
    assert!(
        blocked > 0 && penalty > 0,
        "{blocked} blocked, {penalty} penalty zones"
    );
    let message = serde_json::to_value(&zones).unwrap();
    let all = message["zoneSet"]["zones"].as_array().unwrap();
    let ids: std::collections::HashSet<&str> =
        all.iter().map(|z| z["zoneId"].as_str().unwrap()).collect();
    assert_eq!(ids.len(), all.len(), "zone ids are unique");
    for z in all {
        let p: Vec<[f64; 2]> = z["vertices"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| [f(&v["x"]), f(&v["y"])])
            .collect();
        let twice_area: f64 = (0..p.len())
            .map(|k| p[k][0] * p[(k + 1) % p.len()][1] - p[(k + 1) % p.len()][0] * p[k][1])
            .sum();
        assert!(
            p.len() >= 4 && twice_area > 0.0,
            "{} is counterclockwise",
            z["zoneId"]
        );
    }
    let g = &map.grid;
    let quarter = g.resolution_m / 4.0;
    for i in 0..g.nx {
        for j in 0..g.ny {
            let k = g.index(i, j);
            if map.occupied[k] {
                continue;
            }
            let [x, y] = g.centre(i, j);
            // A point of the cell inside the room and on no cell edge.
            let q = [
                x + if i + 1 == g.nx { -quarter } else { quarter },
                y + if j + 1 == g.ny { -quarter } else { quarter },
            ];
            let covered = |kind: &str, factor: Option<f64>| {
                all.iter().any(|z| {
                    z["zoneType"] == kind
                        && factor.is_none_or(|f0| (f(&z["penaltyFactor"]) - f0).abs() < 1e-12)
                        && contains(z["vertices"].as_array().unwrap(), q)
                })
            };
            let v = map.values[k];
            if v < threshold || v.is_nan() {
                assert!(
                    covered("BLOCKED", None),
                    "cell ({i}, {j}) at {v} dB is blocked"
                );
                continue;
            }
            let penalty = ((threshold + band - v) / band).clamp(0.0, 1.0);
            for level in 1..=levels {
                let factor = level as f64 / levels as f64;
                if penalty > (level - 1) as f64 / levels as f64 {
                    assert!(
                        covered("PENALTY", Some(factor)),
                        "cell ({i}, {j}) at {v} dB has penalty ≥ {factor}"
                    );
                }
            }
        }
    }
}
