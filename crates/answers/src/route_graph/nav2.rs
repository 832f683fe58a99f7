//! Nav2 Route Server GeoJSON graphs (`nav2_route`), read by the rules of its GeoJSON loader
//! (`geojson_graph_file_loader.cpp`) and written back with our scores in each edge's
//! `metadata`, where its scorers and operations look.
//!
//! The loader's rules, and where we are stricter than it (it wraps or truncates what we refuse):
//! * `features`: Point features are nodes, LineString/MultiLineString features edges, other
//!   geometry types are ignored; at least one node and one edge.
//! * `properties.id` (nodes and edges), `startid`, `endid`: unsigned integers. The loader
//!   converts any number (a float truncated, a negative wrapped); we take integers of
//!   0…2³²−1, unique across nodes and edges as its README asks (it keeps the last of two
//!   nodes of one id silently).
//! * `startid`/`endid` name existing nodes; edges are directed; self-loops are allowed.
//! * `cost`: a number; `overridable`: a boolean (default true); an edge that is not
//!   overridable needs a cost above 0 (the planner refuses the graph otherwise).
//! * `frame`: a string (default `map`). The loader transforms other frames through TF; we have
//!   no TF, so a node must be in `map` (or give no frame), the scenario's frame.
//! * `metadata`: an object whose values are booleans, numbers, strings, objects (recursively)
//!   or arrays of booleans, numbers and strings (no nulls, no arrays of arrays or objects).
//! * `operations`: an object or an array of objects with a string `type`, a `trigger` of
//!   `NODE`, `ON_ENTER` or `ON_EXIT`, and optional `metadata` as above.
//! * An edge's geometry is not read: the route server drives straight from node to node, and
//!   so do we when we score it.

use super::Annotation;
use irs_model::input::FieldError;
use irs_model::scenario::route_graph::{GraphEdge, GraphNode};
use serde_json::{Map, Value, json};
use std::collections::HashMap;

/// The nodes and edges of a GeoJSON graph, in feature order; errors name the feature and
/// field under `prefix`.
pub(super) fn read(
    document: &Value,
    prefix: &str,
) -> Result<(Vec<GraphNode>, Vec<GraphEdge>), FieldError> {
    let field = |rest: &str| format!("{prefix}{rest}");
    let features = document
        .get("features")
        .ok_or_else(|| FieldError::new(field("features"), "required, but missing"))?
        .as_array()
        .ok_or_else(|| FieldError::new(field("features"), "must be an array of features"))?;
    let mut nodes = Vec::new();
    let mut node_of_id: HashMap<u64, usize> = HashMap::new();
    // The edges as (feature index, id, startid, endid), resolved once every node is known.
    let mut pending = Vec::new();
    let mut ids: HashMap<u64, usize> = HashMap::new();
    for (k, feature) in features.iter().enumerate() {
        let here = |rest: &str| field(&format!("features[{k}].{rest}"));
        let kind = feature
            .get("geometry")
            .and_then(|g| g.get("type"))
            .ok_or_else(|| FieldError::new(here("geometry.type"), "required, but missing"))?
            .as_str()
            .ok_or_else(|| FieldError::new(here("geometry.type"), "must be a string"))?;
        if !matches!(kind, "Point" | "LineString" | "MultiLineString") {
            continue;
        }
        let properties = feature
            .get("properties")
            .and_then(Value::as_object)
            .ok_or_else(|| FieldError::new(here("properties"), "required: an object"))?;
        let id = unsigned(properties, "id", &here("properties.id"))?;
        if let Some(other) = ids.insert(id, k) {
            return Err(FieldError::new(
                here("properties.id"),
                format!(
                    "id {id} is also the id of features[{other}]; ids are unique across nodes and edges"
                ),
            ));
        }
        if let Some(m) = properties.get("metadata") {
            metadata(m, &here("properties.metadata"))?;
        }
        if let Some(o) = properties.get("operations") {
            operations(o, &here("properties.operations"))?;
        }
        if kind == "Point" {
            match properties.get("frame") {
                None => {}
                Some(Value::String(f)) if f.is_empty() || f == "map" => {}
                Some(Value::String(f)) => {
                    return Err(FieldError::new(
                        here("properties.frame"),
                        format!(
                            "{f:?}: the graph's nodes must be in the scenario's frame, \"map\""
                        ),
                    ));
                }
                Some(_) => {
                    return Err(FieldError::new(
                        here("properties.frame"),
                        "must be a string",
                    ));
                }
            }
            let position = point(feature.get("geometry").and_then(|g| g.get("coordinates")))
                .ok_or_else(|| {
                    FieldError::new(here("geometry.coordinates"), "must be [x, y] (numbers, m)")
                })?;
            node_of_id.insert(id, nodes.len());
            nodes.push((
                k,
                GraphNode {
                    id: id.to_string(),
                    position,
                },
            ));
        } else {
            let start = unsigned(properties, "startid", &here("properties.startid"))?;
            let end = unsigned(properties, "endid", &here("properties.endid"))?;
            let cost = match properties.get("cost") {
                None => None,
                Some(Value::Number(n)) => n.as_f64(),
                Some(_) => {
                    return Err(FieldError::new(here("properties.cost"), "must be a number"));
                }
            };
            let overridable = match properties.get("overridable") {
                None => true,
                Some(Value::Bool(b)) => *b,
                Some(_) => {
                    return Err(FieldError::new(
                        here("properties.overridable"),
                        "must be true or false",
                    ));
                }
            };
            if !overridable && cost.is_none_or(|c| c <= 0.0) {
                return Err(FieldError::new(
                    here("properties.cost"),
                    "an edge that is not overridable needs a cost above 0 (nav2_route refuses the graph otherwise)",
                ));
            }
            pending.push((k, id, start, end));
        }
    }
    if nodes.is_empty() || pending.is_empty() {
        return Err(FieldError::new(
            field("features"),
            "a route graph needs at least one node (Point) and one edge (LineString or MultiLineString)",
        ));
    }
    let mut edges = Vec::with_capacity(pending.len());
    for (k, id, start, end) in pending {
        let resolve = |which: &str, node_id: u64| {
            node_of_id.get(&node_id).copied().ok_or_else(|| {
                FieldError::new(
                    field(&format!("features[{k}].properties.{which}")),
                    format!("no node has id {node_id}"),
                )
            })
        };
        let (from, to) = (resolve("startid", start)?, resolve("endid", end)?);
        edges.push(GraphEdge {
            id: id.to_string(),
            from,
            to,
            points: vec![nodes[from].1.position, nodes[to].1.position],
        });
    }
    let nodes = nodes.into_iter().map(|(_, n)| n).collect();
    Ok((nodes, edges))
}

/// The feature index of each node, for errors about a node's position.
pub(super) fn node_features(document: &Value) -> Vec<usize> {
    features_of(document, |kind| kind == "Point")
}

/// The feature index of each edge, in the order [`read`] lists the edges.
fn edge_features(document: &Value) -> Vec<usize> {
    features_of(document, |kind| {
        kind == "LineString" || kind == "MultiLineString"
    })
}

fn features_of(document: &Value, wanted: impl Fn(&str) -> bool) -> Vec<usize> {
    document["features"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
        .filter(|(_, f)| f["geometry"]["type"].as_str().is_some_and(&wanted))
        .map(|(k, _)| k)
        .collect()
}

fn unsigned(properties: &Map<String, Value>, key: &str, path: &str) -> Result<u64, FieldError> {
    let value = properties
        .get(key)
        .ok_or_else(|| FieldError::new(path, "required, but missing"))?;
    value
        .as_u64()
        .filter(|&v| v <= u64::from(u32::MAX))
        .ok_or_else(|| {
            FieldError::new(
                path,
                format!("{value} is not an unsigned integer of at most 4294967295 (nav2_route reads ids as unsigned int)"),
            )
        })
}

fn point(coordinates: Option<&Value>) -> Option<[f64; 2]> {
    let c = coordinates?.as_array()?;
    let (x, y) = (c.first()?.as_f64()?, c.get(1)?.as_f64()?);
    Some([x, y])
}

/// A metadata object as nav2_route converts it.
fn metadata(value: &Value, path: &str) -> Result<(), FieldError> {
    let object = value
        .as_object()
        .ok_or_else(|| FieldError::new(path, "must be an object"))?;
    for (key, v) in object {
        let here = format!("{path}.{key}");
        match v {
            Value::Bool(_) | Value::Number(_) | Value::String(_) => {}
            Value::Object(_) => metadata(v, &here)?,
            Value::Array(items) => {
                for (k, item) in items.iter().enumerate() {
                    if !matches!(item, Value::Bool(_) | Value::Number(_) | Value::String(_)) {
                        return Err(FieldError::new(
                            format!("{here}[{k}]"),
                            "nav2_route converts arrays of booleans, numbers and strings only",
                        ));
                    }
                }
            }
            Value::Null => {
                return Err(FieldError::new(
                    here,
                    "null is not a metadata value nav2_route converts",
                ));
            }
        }
    }
    Ok(())
}

fn operations(value: &Value, path: &str) -> Result<(), FieldError> {
    let items: Vec<(String, &Value)> = match value {
        Value::Object(o) => o.iter().map(|(k, v)| (format!("{path}.{k}"), v)).collect(),
        Value::Array(a) => a
            .iter()
            .enumerate()
            .map(|(k, v)| (format!("{path}[{k}]"), v))
            .collect(),
        _ => {
            return Err(FieldError::new(
                path,
                "must be an object or an array of operations",
            ));
        }
    };
    for (here, op) in items {
        let op = op
            .as_object()
            .ok_or_else(|| FieldError::new(&here, "an operation must be an object"))?;
        if !op.get("type").is_some_and(Value::is_string) {
            return Err(FieldError::new(
                format!("{here}.type"),
                "required: a string",
            ));
        }
        match op.get("trigger").and_then(Value::as_str) {
            Some("NODE" | "ON_ENTER" | "ON_EXIT") => {}
            _ => {
                return Err(FieldError::new(
                    format!("{here}.trigger"),
                    "required: NODE, ON_ENTER or ON_EXIT",
                ));
            }
        }
        if let Some(m) = op.get("metadata") {
            metadata(m, &format!("{here}.metadata"))?;
        }
    }
    Ok(())
}

/// The graph as given with each edge's scores in `metadata.irs_planner` (and, at a
/// threshold with a penalty band, `metadata.penalty` for nav2_route's PenaltyScorer, set on the
/// edges within the band and removed from the others), and the
/// collection's foreign member `irs_planner` (RFC 7946 §6.1, which the loader ignores) saying
/// what was scored and which edges to close.
pub(super) fn annotate(document: &Value, annotation: &Annotation) -> Value {
    let mut out = document.clone();
    let features = edge_features(document);
    for (edge, &k) in features.iter().enumerate() {
        let properties = &mut out["features"][k]["properties"];
        let metadata = properties
            .as_object_mut()
            .expect("checked when read")
            .entry("metadata")
            .or_insert_with(|| json!({}));
        let edge_scores = annotation.edge_json(edge);
        let m = metadata.as_object_mut().expect("checked when read");
        // With a band the penalties are ours: an edge outside it loses one written before (a
        // graph annotated once and scored again), so the scorer never reads a stale one.
        if annotation.query.penalty_band.is_some() {
            match annotation.penalty(edge) {
                Some(penalty) => m.insert("penalty".into(), json!(penalty)),
                None => m.remove("penalty"),
            };
        }
        m.insert("irs_planner".into(), edge_scores);
    }
    out["irs_planner"] = annotation.summary_json();
    out
}

/// A graph of ours as a Nav2 GeoJSON document: Point nodes and MultiLineString edges with
/// their ids (integers, as the loader reads them), nodes in the `map` frame.
pub(super) fn document(nodes: &[GraphNode], edges: &[GraphEdge]) -> Value {
    let id = |text: &str| text.parse::<u64>().expect("our ids are integers");
    let mut features = Vec::with_capacity(nodes.len() + edges.len());
    for n in nodes {
        features.push(json!({
            "type": "Feature",
            "properties": {"id": id(&n.id), "frame": "map"},
            "geometry": {"type": "Point", "coordinates": n.position},
        }));
    }
    for e in edges {
        features.push(json!({
            "type": "Feature",
            "properties": {"id": id(&e.id), "startid": id(&nodes[e.from].id), "endid": id(&nodes[e.to].id)},
            "geometry": {"type": "MultiLineString", "coordinates": [e.points]},
        }));
    }
    json!({"type": "FeatureCollection", "name": "irs-planner roadmap", "features": features})
}
