//! Open-RMF nav graphs (the YAML `rmf_building_map_tools` generates and `rmf_fleet_adapter`'s
//! `parse_graph.cpp` reads), one level at a time, and written back with our scores as an extra
//! key of each lane's options, which `parse_graph` ignores.
//!
//! The reader's rules (parse_graph's, and where we are stricter):
//! * `levels` is a map of levels; we read one (`route_graph.level`, or the only one), since a
//!   scenario is one floor. Its `vertices` are `[x, y, {options}]` and its `lanes`
//!   `[i, j, {options}]`, i and j indices into the level's vertices (parse_graph indexes past
//!   the end; we refuse it). Lanes are directed: a two-way lane is written twice.
//! * Vertex options: `name` (a string; two vertices may not share a non-empty one), the flags
//!   `is_parking_spot`, `is_holding_point`, `is_passthrough_point`, `is_charger` (booleans),
//!   `mutex` and `lift` (strings), `merge_radius` (a number); other keys are ignored.
//! * Lane options: `orientation_constraint` (`forward` or `backward`), `speed_limit` (a number,
//!   m/s), `door_name`, `dock_name`, `mutex`, `demo_mock_floor_name` (strings; the last needs
//!   `demo_mock_lift_name`); other keys are ignored.
//! * Lane indices, which Open-RMF's lane closures and speed limits name, are the lanes' order in
//!   the file on a one-level graph (a lane with a dock entry event, or lifts joining levels,
//!   add lanes after them or shift later ones: docs/api.md says when closures stay valid).

use super::Annotation;
use irs_model::input::FieldError;
use irs_model::scenario::route_graph::{GraphEdge, GraphNode, GraphSource};
use serde_json::{Map, Value, json};
use std::collections::HashMap;

/// A nav graph's YAML text as a JSON value (`.nan` and `.inf`, which JSON cannot hold, become
/// null, which the reader then refuses wherever it reads a number).
pub(super) fn parse_yaml(text: &str) -> Result<Value, String> {
    let value: Value = serde_saphyr::from_str(text).map_err(|e| e.to_string())?;
    Ok(value)
}

/// The level read, its vertices as nodes and its lanes as edges; errors name the level's
/// field under `prefix`.
pub(super) fn read(
    document: &Value,
    level: Option<&str>,
    prefix: &str,
) -> Result<(String, Vec<GraphNode>, Vec<GraphEdge>), FieldError> {
    let levels = document
        .get("levels")
        .ok_or_else(|| FieldError::new(format!("{prefix}levels"), "required, but missing"))?
        .as_object()
        .ok_or_else(|| FieldError::new(format!("{prefix}levels"), "must be a map of levels"))?;
    let name = match level {
        Some(name) => {
            if !levels.contains_key(name) {
                return Err(FieldError::new(
                    "route_graph.level",
                    format!(
                        "the graph has no level {name:?} (it has {:?})",
                        levels.keys().collect::<Vec<_>>()
                    ),
                ));
            }
            name.to_string()
        }
        None if levels.len() == 1 => levels.keys().next().expect("one").clone(),
        None => {
            return Err(FieldError::new(
                "route_graph.level",
                format!(
                    "the graph has {} levels: name the one to read",
                    levels.len()
                ),
            ));
        }
    };
    let here = format!("{prefix}levels.{name}.");
    let data = levels[&name]
        .as_object()
        .ok_or_else(|| FieldError::new(here.trim_end_matches('.'), "a level must be a map"))?;
    let list = |key: &str| -> Result<&Vec<Value>, FieldError> {
        data.get(key)
            .ok_or_else(|| FieldError::new(format!("{here}{key}"), "required, but missing"))?
            .as_array()
            .ok_or_else(|| FieldError::new(format!("{here}{key}"), "must be a list"))
    };
    let mut nodes = Vec::new();
    let mut names: HashMap<&str, usize> = HashMap::new();
    for (k, vertex) in list("vertices")?.iter().enumerate() {
        let field = format!("{here}vertices[{k}]");
        let (x, y, options) = triple(vertex, &field, "[x, y, {options}]")?;
        let (x, y) = (
            x.as_f64()
                .ok_or_else(|| FieldError::new(format!("{field}[0]"), "x must be a number (m)"))?,
            y.as_f64()
                .ok_or_else(|| FieldError::new(format!("{field}[1]"), "y must be a number (m)"))?,
        );
        check_options(options, &format!("{field}[2]"), VERTEX_OPTIONS)?;
        if let Some(vertex_name) = options
            .get("name")
            .and_then(Value::as_str)
            .filter(|n| !n.is_empty())
            && let Some(other) = names.insert(vertex_name, k)
        {
            return Err(FieldError::new(
                format!("{field}[2].name"),
                format!(
                    "{vertex_name:?} is also the name of vertices[{other}] (parse_graph refuses duplicated waypoint names)"
                ),
            ));
        }
        nodes.push(GraphNode {
            id: k.to_string(),
            position: [x, y],
        });
    }
    let mut edges = Vec::new();
    for (k, lane) in list("lanes")?.iter().enumerate() {
        let field = format!("{here}lanes[{k}]");
        let (i, j, options) = triple(lane, &field, "[i, j, {options}]")?;
        let index = |v: &Value, at: usize| {
            v.as_u64()
                .map(|v| v as usize)
                .filter(|&v| v < nodes.len())
                .ok_or_else(|| {
                    FieldError::new(
                        format!("{field}[{at}]"),
                        format!(
                            "{v} is not the index of one of the level's {} vertices",
                            nodes.len()
                        ),
                    )
                })
        };
        let (from, to) = (index(i, 0)?, index(j, 1)?);
        check_options(options, &format!("{field}[2]"), LANE_OPTIONS)?;
        if let Some(o) = options.get("orientation_constraint")
            && !matches!(o.as_str(), Some("forward" | "backward"))
        {
            return Err(FieldError::new(
                format!("{field}[2].orientation_constraint"),
                "expected forward or backward",
            ));
        }
        if options.contains_key("demo_mock_floor_name")
            && !options.contains_key("demo_mock_lift_name")
        {
            return Err(FieldError::new(
                format!("{field}[2].demo_mock_lift_name"),
                "required with demo_mock_floor_name",
            ));
        }
        edges.push(GraphEdge {
            id: k.to_string(),
            from,
            to,
            points: vec![nodes[from].position, nodes[to].position],
        });
    }
    if nodes.is_empty() || edges.is_empty() {
        return Err(FieldError::new(
            here.trim_end_matches('.'),
            "a route graph needs at least one vertex and one lane",
        ));
    }
    Ok((name, nodes, edges))
}

/// What an option must be.
#[derive(Clone, Copy)]
enum Kind {
    Bool,
    Number,
    Text,
}

const VERTEX_OPTIONS: &[(&str, Kind)] = &[
    ("name", Kind::Text),
    ("is_parking_spot", Kind::Bool),
    ("is_holding_point", Kind::Bool),
    ("is_passthrough_point", Kind::Bool),
    ("is_charger", Kind::Bool),
    ("mutex", Kind::Text),
    ("lift", Kind::Text),
    ("merge_radius", Kind::Number),
];

const LANE_OPTIONS: &[(&str, Kind)] = &[
    ("orientation_constraint", Kind::Text),
    ("speed_limit", Kind::Number),
    ("door_name", Kind::Text),
    ("dock_name", Kind::Text),
    ("mutex", Kind::Text),
    ("demo_mock_floor_name", Kind::Text),
    ("demo_mock_lift_name", Kind::Text),
];

/// An entry `[a, b, {options}]`.
fn triple<'v>(
    value: &'v Value,
    field: &str,
    shape: &str,
) -> Result<(&'v Value, &'v Value, &'v Map<String, Value>), FieldError> {
    match value.as_array().map(Vec::as_slice) {
        Some([a, b, Value::Object(options)]) => Ok((a, b, options)),
        _ => Err(FieldError::new(field, format!("must be {shape}"))),
    }
}

fn check_options(
    options: &Map<String, Value>,
    field: &str,
    known: &[(&str, Kind)],
) -> Result<(), FieldError> {
    for (key, kind) in known {
        let Some(v) = options.get(*key) else { continue };
        let ok = match kind {
            Kind::Bool => v.is_boolean(),
            Kind::Number => v.is_number(),
            Kind::Text => v.is_string(),
        };
        if !ok {
            let what = match kind {
                Kind::Bool => "true or false",
                Kind::Number => "a number",
                Kind::Text => "a string",
            };
            return Err(FieldError::new(
                format!("{field}.{key}"),
                format!("must be {what}"),
            ));
        }
    }
    Ok(())
}

/// Open-RMF's `LaneRequest` closing the lanes `closed` (lane indices).
pub(super) fn lane_request(closed: &[String]) -> Value {
    let lanes: Vec<u64> = closed
        .iter()
        .map(|id| id.parse().expect("lane ids are indices"))
        .collect();
    json!({
        "message": "rmf_fleet_msgs/msg/LaneRequest",
        "topic": "lane_closure_requests",
        "request": {"fleet_name": "", "open_lanes": [], "close_lanes": lanes},
    })
}

/// The nav graph's YAML with each lane's scores under `irs_planner` in its options, and a
/// top-level `irs_planner` saying what was scored and which lanes to close (parse_graph reads
/// neither).
pub(super) fn annotate(document: &Value, source: &GraphSource, annotation: &Annotation) -> String {
    let mut out = document.clone();
    let level = source.level.as_deref().expect("a nav graph has a level");
    if let Some(lanes) = out["levels"][level]["lanes"].as_array_mut() {
        for (k, lane) in lanes.iter_mut().enumerate() {
            let mut scores = annotation.edge_json(k);
            if let Some(penalty) = annotation.penalty(k) {
                scores["penalty"] = json!(penalty);
            }
            lane[2]["irs_planner"] = scores;
        }
    }
    let mut summary = annotation.summary_json();
    summary["level"] = json!(level);
    out["irs_planner"] = summary;
    serde_saphyr::to_string(&out).expect("a JSON value is YAML")
}

/// A graph of ours as an Open-RMF nav graph of one level: vertices with empty names, lanes in
/// edge order (so an edge's index is its lane index).
pub(super) fn document(nodes: &[GraphNode], edges: &[GraphEdge], level: &str) -> Value {
    let vertices: Vec<Value> = nodes
        .iter()
        .map(|n| json!([n.position[0], n.position[1], {"name": ""}]))
        .collect();
    let lanes: Vec<Value> = edges.iter().map(|e| json!([e.from, e.to, {}])).collect();
    json!({
        "building_name": "irs-planner roadmap",
        "levels": {level: {"vertices": vertices, "lanes": lanes}},
    })
}
