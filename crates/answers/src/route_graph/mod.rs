//! Route graphs in and out (docs/api.md "Route graphs"): a scenario's `route_graph` member
//! read into the model's [`RouteGraph`], and a graph scored on a map written back in its own
//! format with our scores where its stack keeps extra data ([`nav2`], [`rmf`]), or as our own
//! JSON report ([`GraphReport`]) with the run-time closures each stack takes.
//!
//! In a scenario document the graph is `{"format": "nav2_geojson", "graph": {…}}` (the
//! GeoJSON object) or `{"format": "rmf_nav_graph", "graph": {…}}` (the nav graph YAML's data
//! as JSON; the level is `level`, or the only one). In a scenario file given to the CLI,
//! `{"file": "lanes.geojson"}` names the graph's file relative to the scenario file instead
//! ([`resolve_graph_reference`]); the format follows from the extension unless given.

pub mod nav2;
pub mod rmf;

use crate::mapfile::ReadFile;
use irs_model::input::FieldError;
use irs_model::planner::route_graph::EdgeScore;
use irs_model::radiomap::Unit;
use irs_model::scenario::Grid;
use irs_model::scenario::route_graph::{
    GraphFormat, GraphSource, MAX_GRAPH_EDGES, MAX_GRAPH_NODES, RouteGraph,
};
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};
use std::path::Path;
use std::sync::Arc;

/// Largest route graph file the CLI reads (bytes).
pub const MAX_GRAPH_FILE_BYTES: u64 = 32 << 20;

/// A format's name in documents and queries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FormatName {
    /// [`GraphFormat::Nav2GeoJson`].
    Nav2Geojson,
    /// [`GraphFormat::RmfNavGraph`].
    RmfNavGraph,
}

impl From<FormatName> for GraphFormat {
    fn from(f: FormatName) -> GraphFormat {
        match f {
            FormatName::Nav2Geojson => GraphFormat::Nav2GeoJson,
            FormatName::RmfNavGraph => GraphFormat::RmfNavGraph,
        }
    }
}

impl From<GraphFormat> for FormatName {
    fn from(f: GraphFormat) -> FormatName {
        match f {
            GraphFormat::Nav2GeoJson => FormatName::Nav2Geojson,
            GraphFormat::RmfNavGraph => FormatName::RmfNavGraph,
        }
    }
}

/// The `route_graph` member of a scenario document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GraphDocument {
    /// The graph's format.
    pub format: FormatName,
    /// Open-RMF: the level read (default: the graph's only level).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub level: Option<String>,
    /// The graph as its stack writes it (for Open-RMF, the YAML's data).
    pub graph: Value,
}

impl GraphDocument {
    /// The model's graph, every node inside the grid's rectangle; errors name the field under
    /// `route_graph.`.
    pub fn validated(self, grid: &Grid) -> Result<RouteGraph, FieldError> {
        let format = GraphFormat::from(self.format);
        let (nodes, edges, level) = match format {
            GraphFormat::Nav2GeoJson => {
                if self.level.is_some() {
                    return Err(FieldError::new(
                        "route_graph.level",
                        "only an Open-RMF nav graph has levels",
                    ));
                }
                let (nodes, edges) = nav2::read(&self.graph, "route_graph.graph.")?;
                (nodes, edges, None)
            }
            GraphFormat::RmfNavGraph => {
                let (level, nodes, edges) =
                    rmf::read(&self.graph, self.level.as_deref(), "route_graph.graph.")?;
                (nodes, edges, Some(level))
            }
        };
        if nodes.len() > MAX_GRAPH_NODES || edges.len() > MAX_GRAPH_EDGES {
            return Err(FieldError::new(
                "route_graph.graph",
                format!(
                    "{} nodes and {} edges: at most {MAX_GRAPH_NODES} nodes and {MAX_GRAPH_EDGES} edges",
                    nodes.len(),
                    edges.len()
                ),
            ));
        }
        let features = match format {
            GraphFormat::Nav2GeoJson => nav2::node_features(&self.graph),
            GraphFormat::RmfNavGraph => Vec::new(),
        };
        for (k, node) in nodes.iter().enumerate() {
            let [x, y] = node.position;
            if grid.snap(x, y).is_none() {
                let field = match &level {
                    Some(level) => format!("route_graph.graph.levels.{level}.vertices[{k}]"),
                    None => format!(
                        "route_graph.graph.features[{}].geometry.coordinates",
                        features[k]
                    ),
                };
                return Err(FieldError::new(
                    field,
                    format!("node {} at ({x}, {y}) lies outside the room", node.id),
                ));
            }
        }
        Ok(RouteGraph {
            nodes,
            edges,
            source: Arc::new(GraphSource {
                format,
                level,
                document: self.graph.to_string().into(),
            }),
        })
    }
}

impl From<&RouteGraph> for GraphDocument {
    fn from(g: &RouteGraph) -> GraphDocument {
        GraphDocument {
            format: g.source.format.into(),
            level: match g.source.format {
                GraphFormat::Nav2GeoJson => None,
                GraphFormat::RmfNavGraph => g.source.level.clone(),
            },
            graph: source_document(&g.source),
        }
    }
}

/// The graph's document as a JSON value: the text the model keeps was written from one.
fn source_document(source: &GraphSource) -> Value {
    serde_json::from_str(&source.document).expect("a graph's document is the JSON it was read from")
}

/// Replaces a file reference `route_graph.file` in a scenario document by the graph read with
/// `read` from that path relative to `base` (`.geojson`/`.json`: Nav2; `.yaml`/`.yml`:
/// Open-RMF, unless `route_graph.format` says). A document without one is left as it is.
pub fn resolve_graph_reference(
    document: &mut Value,
    base: &Path,
    read: ReadFile,
) -> Result<(), FieldError> {
    let Some(member) = document
        .get_mut("route_graph")
        .and_then(Value::as_object_mut)
    else {
        return Ok(());
    };
    let Some(reference) = member.remove("file") else {
        return Ok(());
    };
    let field = |reason: String| FieldError::new("route_graph.file", reason);
    let name = reference
        .as_str()
        .ok_or_else(|| field("must be the path of a graph file".into()))?;
    if member.contains_key("graph") {
        return Err(FieldError::new(
            "route_graph.graph",
            "comes from the file named in route_graph.file; give one or the other",
        ));
    }
    let path = base.join(name);
    let format = match member.get("format") {
        Some(f) => serde_json::from_value::<FormatName>(f.clone()).map_err(|_| {
            FieldError::new(
                "route_graph.format",
                "expected nav2_geojson or rmf_nav_graph",
            )
        })?,
        None => match path.extension().and_then(|e| e.to_str()) {
            Some("geojson" | "json") => FormatName::Nav2Geojson,
            Some("yaml" | "yml") => FormatName::RmfNavGraph,
            _ => {
                return Err(field(format!(
                    "{}: name the format in route_graph.format (the extension is neither .geojson, .json, .yaml nor .yml)",
                    path.display()
                )));
            }
        },
    };
    let bytes =
        read(&path, MAX_GRAPH_FILE_BYTES).map_err(|e| field(format!("{}: {e}", path.display())))?;
    let text = String::from_utf8(bytes)
        .map_err(|_| field(format!("{}: not UTF-8 text", path.display())))?;
    let graph: Value = match format {
        FormatName::Nav2Geojson => crate::scenario::document(&text)
            .map_err(|e| field(format!("{}: {}", path.display(), e)))?,
        FormatName::RmfNavGraph => {
            rmf::parse_yaml(&text).map_err(|e| field(format!("{}: {e}", path.display())))?
        }
    };
    member.insert(
        "format".into(),
        serde_json::to_value(format).expect("a name"),
    );
    member.insert("graph".into(), graph);
    Ok(())
}

/// Rejects `route_graph.file` in a document that was not read from a file (an HTTP body).
pub fn reject_graph_reference(document: &Value) -> Result<(), FieldError> {
    match document.get("route_graph").and_then(|g| g.get("file")) {
        Some(_) => Err(FieldError::new(
            "route_graph.file",
            "a graph file is read only where files are: in a scenario file given to the CLI; \
             over HTTP send the graph inline as route_graph.graph",
        )),
        None => Ok(()),
    }
}

/// What a score is written against: the map, the unit, an optional threshold (closing the
/// edges below it) and penalty band (a penalty for edges that meet it by less).
#[derive(Debug, Clone, PartialEq)]
pub struct ScoreQuery {
    /// The map scored on.
    pub map_id: String,
    /// The values' unit.
    pub unit: Unit,
    /// Edges whose worst value is below it are closed.
    pub threshold: Option<f64>,
    /// Width of the band above the threshold whose edges get a penalty in (0, 1].
    pub penalty_band: Option<f64>,
}

/// A graph's scores on a map and what they imply at a threshold: the input of every writer.
pub struct Annotation<'a> {
    /// The graph.
    pub graph: &'a RouteGraph,
    /// One score per edge.
    pub scores: &'a [EdgeScore],
    /// What was asked.
    pub query: &'a ScoreQuery,
}

impl Annotation<'_> {
    /// Whether edge `k` is open at the query's threshold (every edge is without one, unless it
    /// meets a cell without a value).
    pub fn open(&self, k: usize) -> bool {
        match self.query.threshold {
            Some(t) => self.scores[k].open_at(t),
            None => self.scores[k].worst.is_some(),
        }
    }

    /// The penalty of an open edge that meets the threshold by less than the band:
    /// 1 − (worst − threshold)/band, in (0, 1].
    pub fn penalty(&self, k: usize) -> Option<f64> {
        let (t, band) = (self.query.threshold?, self.query.penalty_band?);
        let worst = self.scores[k].worst?;
        (self.open(k) && worst < t + band).then(|| 1.0 - (worst - t) / band)
    }

    /// The ids of the edges to close, in graph order.
    pub fn closed(&self) -> Vec<&str> {
        (0..self.scores.len())
            .filter(|&k| !self.open(k))
            .map(|k| self.graph.edges[k].id.as_str())
            .collect()
    }

    /// Edge `k`'s scores as metadata every stack keeps: booleans, numbers (floats written with
    /// a decimal point), strings, and arrays of numbers; no nulls (a missing worst value is
    /// left out), no arrays of objects (nav2_route's loader converts neither).
    pub fn edge_json(&self, k: usize) -> Value {
        let s = &self.scores[k];
        let mut m = serde_json::Map::new();
        m.insert("map_id".into(), json!(self.query.map_id));
        m.insert("unit".into(), json!(self.query.unit.symbol()));
        if let Some(w) = s.worst {
            m.insert("worst_value".into(), json!(w));
        }
        m.insert("worst_at".into(), json!(s.worst_at));
        m.insert("worst_distance_m".into(), json!(s.worst_distance_m));
        m.insert("length_m".into(), json!(s.length_m));
        m.insert("crosses_obstacle".into(), json!(s.crosses_obstacle));
        m.insert("serving_aps".into(), json!(s.serving));
        m.insert(
            "handover_distances_m".into(),
            json!(s.handovers.iter().map(|h| h.distance_m).collect::<Vec<_>>()),
        );
        if let Some(t) = self.query.threshold {
            m.insert("threshold".into(), json!(t));
            m.insert("open".into(), json!(self.open(k)));
        }
        Value::Object(m)
    }

    /// What was scored, and the edges to close at the threshold.
    pub fn summary_json(&self) -> Value {
        json!({
            "map_id": self.query.map_id,
            "unit": self.query.unit.symbol(),
            "threshold": self.query.threshold,
            "penalty_band": self.query.penalty_band,
            "closed_edges": self.closed(),
        })
    }
}

/// One edge in the JSON report.
#[derive(Debug, Serialize)]
pub struct EdgeView {
    /// The edge's id in its graph.
    pub id: String,
    /// Its start node's id.
    pub start: String,
    /// Its end node's id.
    pub end: String,
    /// Polyline length (m).
    pub length_m: f64,
    /// The lowest value of the cells it meets (null: a cell without a value).
    pub worst_value: Option<f64>,
    /// The first cell (i, j) of that value.
    pub worst_cell: [usize; 2],
    /// Where the edge reaches it (x, y).
    pub worst_at: [f64; 2],
    /// How far along the edge (m).
    pub worst_distance_m: f64,
    /// Whether it meets an occupied cell.
    pub crosses_obstacle: bool,
    /// The serving APs in order along it.
    pub serving_aps: Vec<usize>,
    /// Where the serving AP changes.
    pub handovers: Vec<HandoverView>,
    /// How many cells it meets.
    pub cells: usize,
    /// At the threshold: whether it stays open.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub open: Option<bool>,
    /// At the threshold with a band: its penalty.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub penalty: Option<f64>,
}

/// A handover along an edge.
#[derive(Debug, Serialize)]
pub struct HandoverView {
    /// From the edge's start (m).
    pub distance_m: f64,
    /// x (m).
    pub x: f64,
    /// y (m).
    pub y: f64,
    /// The AP before.
    pub from: usize,
    /// The AP after.
    pub to: usize,
}

/// A graph's scores as our own JSON: every edge, the edges to close, and the closures as the
/// graph's stack takes them at run time.
#[derive(Debug, Serialize)]
pub struct GraphReport {
    /// The map scored on.
    pub map_id: String,
    /// The graph's format.
    pub format: FormatName,
    /// The values' unit (symbol).
    pub unit: &'static str,
    /// The threshold, if one was given.
    pub threshold: Option<f64>,
    /// The penalty band, if one was given.
    pub penalty_band: Option<f64>,
    /// Nodes in the graph.
    pub nodes: usize,
    /// One entry per edge, in graph order.
    pub edges: Vec<EdgeView>,
    /// The ids of the edges to close (below the threshold, or meeting a cell without a value).
    pub closed_edges: Vec<String>,
    /// The closures as the stack's run-time request: Nav2's `nav2_msgs/srv/DynamicEdges`
    /// request, or Open-RMF's `rmf_fleet_msgs/msg/LaneRequest`.
    pub closure_request: Value,
}

/// The JSON report of an annotation.
pub fn report(annotation: &Annotation) -> GraphReport {
    let graph = annotation.graph;
    let edges = annotation
        .scores
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let edge = &graph.edges[k];
            EdgeView {
                id: edge.id.clone(),
                start: graph.nodes[edge.from].id.clone(),
                end: graph.nodes[edge.to].id.clone(),
                length_m: s.length_m,
                worst_value: s.worst,
                worst_cell: [s.worst_cell.0, s.worst_cell.1],
                worst_at: s.worst_at,
                worst_distance_m: s.worst_distance_m,
                crosses_obstacle: s.crosses_obstacle,
                serving_aps: s.serving.clone(),
                handovers: s
                    .handovers
                    .iter()
                    .map(|h| HandoverView {
                        distance_m: h.distance_m,
                        x: h.at[0],
                        y: h.at[1],
                        from: h.from,
                        to: h.to,
                    })
                    .collect(),
                cells: s.cells,
                open: annotation.query.threshold.map(|_| annotation.open(k)),
                penalty: annotation.penalty(k),
            }
        })
        .collect();
    let closed: Vec<String> = annotation.closed().into_iter().map(String::from).collect();
    let closure_request = match graph.source.format {
        GraphFormat::Nav2GeoJson => nav2_dynamic_edges(&closed),
        GraphFormat::RmfNavGraph => rmf::lane_request(&closed),
    };
    GraphReport {
        map_id: annotation.query.map_id.clone(),
        format: graph.source.format.into(),
        unit: annotation.query.unit.symbol(),
        threshold: annotation.query.threshold,
        penalty_band: annotation.query.penalty_band,
        nodes: graph.nodes.len(),
        edges,
        closed_edges: closed,
        closure_request,
    }
}

/// Nav2's `DynamicEdges` request closing `closed` (its ids are uint16: an id above 65535 cannot
/// be sent there, and is listed under `not_addressable` instead).
fn nav2_dynamic_edges(closed: &[String]) -> Value {
    let (ids, too_large): (Vec<u64>, Vec<u64>) = closed
        .iter()
        .map(|id| id.parse::<u64>().expect("Nav2 ids are integers"))
        .partition(|&id| id <= u64::from(u16::MAX));
    json!({
        "service": "nav2_msgs/srv/DynamicEdges",
        "request": {"closed_edges": ids, "opened_edges": [], "adjust_edges": []},
        "not_addressable": too_large,
    })
}

/// The graph annotated in its own format: the GeoJSON object, or the nav graph's YAML text.
pub enum Annotated {
    /// A Nav2 GeoJSON graph (`application/geo+json`).
    GeoJson(Value),
    /// An Open-RMF nav graph (`application/yaml`).
    Yaml(String),
}

/// The graph in its own format with the scores added ([`nav2::annotate`], [`rmf::annotate`]).
pub fn annotated(annotation: &Annotation) -> Annotated {
    let source = &annotation.graph.source;
    match source.format {
        GraphFormat::Nav2GeoJson => {
            Annotated::GeoJson(nav2::annotate(&source_document(source), annotation))
        }
        GraphFormat::RmfNavGraph => {
            Annotated::Yaml(rmf::annotate(&source_document(source), source, annotation))
        }
    }
}

/// What a scoring request writes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum GraphOutput {
    /// Our JSON report ([`GraphReport`]).
    #[default]
    Report,
    /// The graph in its own format, annotated ([`annotated`]).
    Graph,
}

impl std::str::FromStr for GraphOutput {
    type Err = String;
    fn from_str(text: &str) -> Result<GraphOutput, String> {
        match text {
            "report" => Ok(GraphOutput::Report),
            "graph" => Ok(GraphOutput::Graph),
            other => Err(format!("expected report or graph, got {other:?}")),
        }
    }
}

/// A scored graph as written.
pub enum Scored {
    /// [`GraphOutput::Report`].
    Report(GraphReport),
    /// [`GraphOutput::Graph`] of a graph written in `format`.
    Graph(Annotated),
}

impl ScoreQuery {
    /// Checks the band: a positive finite width, only with a threshold; errors name
    /// `threshold` or `penalty_band`.
    pub fn validate(&self) -> Result<(), FieldError> {
        if let Some(t) = self.threshold
            && !t.is_finite()
        {
            return Err(FieldError::new("threshold", "must be a finite number"));
        }
        match (self.threshold, self.penalty_band) {
            (_, Some(b)) if !(b.is_finite() && b > 0.0) => Err(FieldError::new(
                "penalty_band",
                "must be a finite number above 0",
            )),
            (None, Some(_)) => Err(FieldError::new(
                "penalty_band",
                "applies only with a threshold",
            )),
            _ => Ok(()),
        }
    }
}

/// The use case: the scenario's route graph scored on `map` (built from that scenario) as
/// `query` asks, written as `output` says. Errors name `route_graph` (the scenario has none),
/// `unit`, `threshold` or `penalty_band`.
pub fn score(
    scenario: &irs_model::scenario::Scenario,
    map: &irs_model::radiomap::RadioMap,
    query: &ScoreQuery,
    output: GraphOutput,
) -> Result<Scored, FieldError> {
    query.validate()?;
    let graph = scenario.route_graph.as_deref().ok_or_else(|| {
        FieldError::new(
            "route_graph",
            "the map's scenario has no route graph: attach one as the scenario's route_graph",
        )
    })?;
    let values = map.values_in(query.unit)?;
    let scores = irs_model::planner::route_graph::score_edges(map, &values, graph);
    let annotation = Annotation {
        graph,
        scores: &scores,
        query,
    };
    Ok(match output {
        GraphOutput::Report => Scored::Report(report(&annotation)),
        GraphOutput::Graph => Scored::Graph(annotated(&annotation)),
    })
}

/// Widest roadmap spacing (m).
pub const MAX_ROADMAP_SPACING_M: f64 = 100.0;

/// A roadmap request: the lattice spacing, the format written, and what it is scored against
/// (with a threshold, only the region meeting it is mapped).
#[derive(Debug, Clone, PartialEq)]
pub struct RoadmapQuery {
    /// Distance between neighbouring nodes along x and y (m), rounded to whole cells.
    pub spacing_m: f64,
    /// The format written.
    pub format: FormatName,
    /// The map, unit and threshold.
    pub score: ScoreQuery,
}

/// The use case of sites without a route graph: a roadmap of the map's free region (at a
/// threshold, its feasible region) as a graph in the format asked, every edge scored as an
/// attached graph's would be. Attached to the scenario as `route_graph`, it reads back to the
/// same graph. Errors name `spacing_m`, `unit`, `threshold` or `penalty_band`.
pub fn roadmap(
    map: &irs_model::radiomap::RadioMap,
    query: &RoadmapQuery,
) -> Result<Annotated, FieldError> {
    query.score.validate()?;
    let grid = &map.grid;
    let spacing = query.spacing_m;
    if !(spacing.is_finite() && spacing >= grid.resolution_m && spacing <= MAX_ROADMAP_SPACING_M) {
        return Err(FieldError::new(
            "spacing_m",
            format!(
                "must lie in [{}, {MAX_ROADMAP_SPACING_M}] m (at least the grid's resolution)",
                grid.resolution_m
            ),
        ));
    }
    let step = (spacing / grid.resolution_m).round() as usize;
    let lattice = (grid.nx.div_ceil(step)) * (grid.ny.div_ceil(step));
    if lattice > MAX_GRAPH_NODES {
        return Err(FieldError::new(
            "spacing_m",
            format!("{lattice} lattice nodes: at most {MAX_GRAPH_NODES}; take a wider spacing"),
        ));
    }
    let values = map.values_in(query.score.unit)?;
    let (nodes, mut edges) =
        irs_model::planner::route_graph::roadmap(map, &values, step, query.score.threshold);
    if edges.is_empty() {
        let field = if query.score.threshold.is_some() {
            "threshold"
        } else {
            "spacing_m"
        };
        return Err(FieldError::new(
            field,
            "no two neighbouring lattice nodes are joined by an open edge: the roadmap would be empty",
        ));
    }
    if edges.len() > MAX_GRAPH_EDGES {
        return Err(FieldError::new(
            "spacing_m",
            format!(
                "{} edges: a route graph holds at most {MAX_GRAPH_EDGES}; take a wider spacing",
                edges.len()
            ),
        ));
    }
    let (document, level) = match query.format {
        FormatName::Nav2Geojson => (nav2::document(&nodes, &edges), None),
        FormatName::RmfNavGraph => {
            // Open-RMF names a lane by its index.
            for (k, e) in edges.iter_mut().enumerate() {
                e.id = k.to_string();
            }
            (
                rmf::document(&nodes, &edges, ROADMAP_LEVEL),
                Some(ROADMAP_LEVEL.to_string()),
            )
        }
    };
    let graph = RouteGraph {
        nodes,
        edges,
        source: Arc::new(GraphSource {
            format: query.format.into(),
            level,
            document: document.to_string().into(),
        }),
    };
    let scores = irs_model::planner::route_graph::score_edges(map, &values, &graph);
    Ok(annotated(&Annotation {
        graph: &graph,
        scores: &scores,
        query: &query.score,
    }))
}

/// The level an Open-RMF roadmap is written on.
pub const ROADMAP_LEVEL: &str = "L1";

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::ScenarioDocument;
    use irs_model::phases::PhaseMode;
    use irs_model::planner::route_graph::score_edges;
    use irs_model::radiomap::{MapKey, Progress, RadioMap};
    use irs_model::scenario::Scenario;

    const NAV2_SAMPLE: &str =
        include_str!("../../../../tests/data/route_graphs/nav2/sample_graph.geojson");
    const NAV2_AWS: &str =
        include_str!("../../../../tests/data/route_graphs/nav2/aws_graph.geojson");
    const RMF_OFFICE: &str =
        include_str!("../../../../tests/data/route_graphs/rmf/office_nav.yaml");

    /// An edit of a graph document, for the refusal cases.
    type Edit = Box<dyn Fn(&mut Value)>;

    /// The paper floor with `graph` attached as a Nav2 graph.
    fn paper_with(graph: Value) -> Result<Scenario, FieldError> {
        Scenario::builtin_with("paper-single-user", |v| {
            v["route_graph"] = json!({"format": "nav2_geojson", "graph": graph});
        })
        .unwrap()
    }

    /// The warehouse with the Open-RMF office graph moved by (−20, +10) m to lie in it.
    fn warehouse_with_office() -> Scenario {
        let mut graph = rmf::parse_yaml(RMF_OFFICE).unwrap();
        for v in graph["levels"]["L1"]["vertices"].as_array_mut().unwrap() {
            v[0] = json!(v[0].as_f64().unwrap() - 20.0);
            v[1] = json!(v[1].as_f64().unwrap() + 10.0);
        }
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/warehouse");
        let mut doc: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("warehouse.json")).unwrap())
                .unwrap();
        doc["route_graph"] = json!({"format": "rmf_nav_graph", "graph": graph});
        Scenario::from_value_with_files(doc, &dir).unwrap()
    }

    fn gain_map(scenario: &Scenario) -> RadioMap {
        let key = MapKey::gain(&scenario.content_hash(), scenario, PhaseMode::Continuous).unwrap();
        crate::map::build(scenario, &key, &Progress::default()).unwrap()
    }

    /// Nav2's own sample graphs read as its loader reads them: every Point a node, every
    /// LineString/MultiLineString an edge (geometry not read, so the self-loop and the
    /// mis-nested LineString of the AWS graph load), directed, ids kept.
    #[test]
    fn nav2_samples_load() {
        for (text, nodes, edges) in [(NAV2_SAMPLE, 9, 24), (NAV2_AWS, 40, 84)] {
            let scenario = paper_with(serde_json::from_str(text).unwrap()).unwrap();
            let graph = scenario.route_graph.as_ref().unwrap();
            assert_eq!((graph.nodes.len(), graph.edges.len()), (nodes, edges));
            // The document round-trips: the canonical form reads back to the same scenario.
            let again = Scenario::from_value(scenario.to_json_value()).unwrap();
            assert_eq!(again.content_hash(), scenario.content_hash());
            assert_eq!(again.route_graph, scenario.route_graph);
        }
        let scenario = paper_with(serde_json::from_str(NAV2_SAMPLE).unwrap()).unwrap();
        let graph = scenario.route_graph.as_ref().unwrap();
        let first = &graph.edges[0];
        assert_eq!(first.id, "9");
        assert_eq!(
            (
                graph.nodes[first.from].id.as_str(),
                graph.nodes[first.to].id.as_str()
            ),
            ("0", "1")
        );
        assert_eq!(first.points, vec![[0.0, 0.0], [1.0, 0.0]]);
        let aws = paper_with(serde_json::from_str(NAV2_AWS).unwrap()).unwrap();
        let aws = aws.route_graph.as_ref().unwrap();
        let looped = aws.edges.iter().find(|e| e.id == "112").unwrap();
        assert_eq!(looped.from, looped.to);
    }

    /// Graphs nav2_route's loader would refuse, wrap or misread are refused, each naming the
    /// feature and field; nothing is attached.
    #[test]
    fn malformed_nav2_graphs_name_the_feature_and_field() {
        let sample: Value = serde_json::from_str(NAV2_SAMPLE).unwrap();
        let cases: Vec<(&str, Edit, &str)> = vec![
            (
                "duplicate id",
                Box::new(|g| g["features"][1]["properties"]["id"] = json!(0)),
                "route_graph.graph.features[1].properties.id",
            ),
            (
                "edge id of a node",
                Box::new(|g| g["features"][9]["properties"]["id"] = json!(3)),
                "route_graph.graph.features[9].properties.id",
            ),
            (
                "float id",
                Box::new(|g| g["features"][2]["properties"]["id"] = json!(2.5)),
                "route_graph.graph.features[2].properties.id",
            ),
            (
                "negative id",
                Box::new(|g| g["features"][2]["properties"]["id"] = json!(-2)),
                "route_graph.graph.features[2].properties.id",
            ),
            (
                "unknown end",
                Box::new(|g| g["features"][9]["properties"]["endid"] = json!(77)),
                "route_graph.graph.features[9].properties.endid",
            ),
            (
                "missing start",
                Box::new(|g| {
                    g["features"][10]["properties"]
                        .as_object_mut()
                        .unwrap()
                        .remove("startid");
                }),
                "route_graph.graph.features[10].properties.startid",
            ),
            (
                "text cost",
                Box::new(|g| g["features"][10]["properties"]["cost"] = json!("1")),
                "route_graph.graph.features[10].properties.cost",
            ),
            (
                "fixed cost 0",
                Box::new(|g| {
                    g["features"][10]["properties"]["overridable"] = json!(false);
                    g["features"][10]["properties"]["cost"] = json!(0.0);
                }),
                "route_graph.graph.features[10].properties.cost",
            ),
            (
                "null metadata",
                Box::new(|g| g["features"][3]["properties"]["metadata"] = json!({"a": null})),
                "route_graph.graph.features[3].properties.metadata.a",
            ),
            (
                "array of objects",
                Box::new(|g| g["features"][3]["properties"]["metadata"] = json!({"a": [{"b": 1}]})),
                "route_graph.graph.features[3].properties.metadata.a[0]",
            ),
            (
                "bad trigger",
                Box::new(|g| {
                    g["features"][0]["properties"]["operations"]["stop"]["trigger"] =
                        json!("SOMETIMES")
                }),
                "route_graph.graph.features[0].properties.operations.stop.trigger",
            ),
            (
                "other frame",
                Box::new(|g| g["features"][4]["properties"]["frame"] = json!("odom")),
                "route_graph.graph.features[4].properties.frame",
            ),
            (
                "outside the room",
                Box::new(|g| g["features"][4]["geometry"]["coordinates"] = json!([40.0, 0.0])),
                "route_graph.graph.features[4].geometry.coordinates",
            ),
            (
                "no coordinates",
                Box::new(|g| g["features"][4]["geometry"]["coordinates"] = json!(["a", 0.0])),
                "route_graph.graph.features[4].geometry.coordinates",
            ),
            (
                "no features",
                Box::new(|g| g["features"] = json!({})),
                "route_graph.graph.features",
            ),
            (
                "no edges",
                Box::new(|g| {
                    g["features"].as_array_mut().unwrap().truncate(9);
                }),
                "route_graph.graph.features",
            ),
        ];
        for (what, edit, field) in cases {
            let mut graph = sample.clone();
            edit(&mut graph);
            let e = paper_with(graph).expect_err(what);
            assert_eq!(e.field, field, "{what}: {e}");
        }
        let e = Scenario::builtin_with("paper-single-user", |v| {
            v["route_graph"] =
                json!({"format": "nav2_geojson", "level": "L1", "graph": sample.clone()});
        })
        .unwrap()
        .unwrap_err();
        assert_eq!(e.field, "route_graph.level");
        let e = Scenario::from_value(json!({"route_graph": {"file": "x.geojson"}})).unwrap_err();
        assert_eq!(e.field, "route_graph.file");
    }

    /// The Open-RMF office graph (rmf_ros2's test resource) on the warehouse floor: vertices as
    /// nodes, lanes as directed edges, lane indices as ids; refused where parse_graph throws.
    #[test]
    fn rmf_nav_graphs_load_and_refuse_what_parse_graph_refuses() {
        let scenario = warehouse_with_office();
        let graph = scenario.route_graph.as_ref().unwrap();
        assert_eq!((graph.nodes.len(), graph.edges.len()), (24, 54));
        assert_eq!(graph.edges[1].id, "1");
        assert_eq!((graph.edges[1].from, graph.edges[1].to), (1, 0));
        assert_eq!(graph.source.level.as_deref(), Some("L1"));
        let again = Scenario::from_value(scenario.to_json_value()).unwrap();
        assert_eq!(again.content_hash(), scenario.content_hash());
        let base: Value = rmf::parse_yaml(RMF_OFFICE).unwrap();
        let cases: Vec<(Edit, &str)> = vec![
            (
                Box::new(|g| g["levels"]["L1"]["lanes"][3][1] = json!(24)),
                "route_graph.graph.levels.L1.lanes[3][1]",
            ),
            (
                Box::new(|g| {
                    g["levels"]["L1"]["lanes"][3][2] = json!({"orientation_constraint": "sideways"})
                }),
                "route_graph.graph.levels.L1.lanes[3][2].orientation_constraint",
            ),
            (
                Box::new(|g| g["levels"]["L1"]["lanes"][3][2] = json!({"speed_limit": "fast"})),
                "route_graph.graph.levels.L1.lanes[3][2].speed_limit",
            ),
            (
                Box::new(|g| {
                    g["levels"]["L1"]["vertices"][5][2] = json!({"name": "magni1_charger"})
                }),
                "route_graph.graph.levels.L1.vertices[18][2].name",
            ),
            (
                Box::new(|g| g["levels"]["L1"]["vertices"][5] = json!([1.0, 2.0])),
                "route_graph.graph.levels.L1.vertices[5]",
            ),
            (
                Box::new(|g| g["levels"]["L2"] = g["levels"]["L1"].clone()),
                "route_graph.level",
            ),
            (
                Box::new(|g| {
                    g.as_object_mut().unwrap().remove("levels");
                }),
                "route_graph.graph.levels",
            ),
        ];
        let paper = |graph: Value| {
            Scenario::builtin_with("paper-single-user", |v| {
                v["route_graph"] = json!({"format": "rmf_nav_graph", "graph": graph});
            })
            .unwrap()
        };
        for (edit, field) in cases {
            let mut graph = base.clone();
            edit(&mut graph);
            let e = paper(graph).unwrap_err();
            assert_eq!(e.field, field, "{e}");
        }
        // The office lies east of the paper floor: its vertices are outside that room.
        let e = paper(base).unwrap_err();
        assert!(
            e.field.starts_with("route_graph.graph.levels.L1.vertices["),
            "{e}"
        );
    }

    /// The annotated graphs are graphs their stacks load: read back by the same rules they
    /// give the same nodes and edges; the edge scores sit in metadata the Nav2 loader converts
    /// (floats with a decimal point, no nulls, no arrays of objects); the closures are the
    /// edges below the threshold.
    #[test]
    fn annotated_graphs_read_back_and_carry_their_scores() {
        let scenario = paper_with(serde_json::from_str(NAV2_AWS).unwrap()).unwrap();
        let map = gain_map(&scenario);
        let graph = scenario.route_graph.as_ref().unwrap();
        let scores = score_edges(&map, &map.values, graph);
        let mut worst: Vec<f64> = scores.iter().filter_map(|s| s.worst).collect();
        worst.sort_by(f64::total_cmp);
        let threshold = worst[worst.len() / 3];
        let query = ScoreQuery {
            map_id: map.id.clone(),
            unit: Unit::GainDb,
            threshold: Some(threshold),
            penalty_band: Some(3.0),
        };
        let annotation = Annotation {
            graph,
            scores: &scores,
            query: &query,
        };
        let Annotated::GeoJson(out) = annotated(&annotation) else {
            panic!("GeoJSON in, GeoJSON out")
        };
        let (nodes, edges) = nav2::read(&out, "").unwrap();
        assert_eq!((&nodes, &edges), (&graph.nodes, &graph.edges));
        // The exported graph, imported again, scores the same on the map.
        let reread = RouteGraph {
            nodes,
            edges,
            source: graph.source.clone(),
        };
        assert_eq!(score_edges(&map, &map.values, &reread), scores);
        let text = serde_json::to_string(&out).unwrap();
        let penalties = regex_lite::Regex::new(r#""penalty":([0-9eE.+-]+)"#).unwrap();
        let written: Vec<&str> = penalties
            .captures_iter(&text)
            .map(|c| c.get(1).unwrap().as_str())
            .collect();
        assert!(!written.is_empty());
        assert!(written.iter().all(|p| p.contains('.')), "{written:?}");
        // Scored again with a narrower band, the annotated graph keeps no stale penalty.
        let mut again = (*graph.source).clone();
        again.document = out.to_string().into();
        let regraph = RouteGraph {
            nodes: graph.nodes.clone(),
            edges: graph.edges.clone(),
            source: std::sync::Arc::new(again),
        };
        let narrow = ScoreQuery {
            penalty_band: Some(0.5),
            ..query.clone()
        };
        let rescored = Annotation {
            graph: &regraph,
            scores: &scores,
            query: &narrow,
        };
        let Annotated::GeoJson(twice) = annotated(&rescored) else {
            panic!("GeoJSON in, GeoJSON out")
        };
        let penalised = |g: &Value| {
            g["features"]
                .as_array()
                .unwrap()
                .iter()
                .filter(|f| f["properties"]["metadata"]["penalty"].is_number())
                .count()
        };
        let within = (0..scores.len())
            .filter(|&k| rescored.penalty(k).is_some())
            .count();
        assert!(
            penalised(&out) > within,
            "a narrower band penalises fewer edges"
        );
        assert_eq!(penalised(&twice), within);
        let written_report = report(&annotation);
        let below: Vec<String> = scores
            .iter()
            .zip(&graph.edges)
            .filter(|(s, _)| !s.open_at(threshold))
            .map(|(_, e)| e.id.clone())
            .collect();
        assert!(!below.is_empty() && below.len() < scores.len());
        assert_eq!(written_report.closed_edges, below);
        assert_eq!(out["irs_planner"]["closed_edges"], json!(below));
        let ids: Vec<u64> = below.iter().map(|id| id.parse().unwrap()).collect();
        assert_eq!(
            written_report.closure_request["request"]["closed_edges"],
            json!(ids)
        );
        for (k, e) in written_report.edges.iter().enumerate() {
            let feature = out["features"]
                .as_array()
                .unwrap()
                .iter()
                .find(|f| f["properties"]["id"].as_u64() == Some(e.id.parse().unwrap()))
                .unwrap();
            let m = &feature["properties"]["metadata"]["irs_planner"];
            assert_eq!(m["worst_value"].as_f64(), e.worst_value);
            assert_eq!(m["open"].as_bool(), e.open);
            assert_eq!(
                feature["properties"]["metadata"]["penalty"].as_f64(),
                e.penalty
            );
            if let Some(p) = e.penalty {
                assert!(p > 0.0 && p <= 1.0 && e.open == Some(true), "edge {k}");
            }
        }

        let office = warehouse_with_office();
        let map = gain_map(&office);
        let graph = office.route_graph.as_ref().unwrap();
        let scores = score_edges(&map, &map.values, graph);
        let query = ScoreQuery {
            map_id: map.id.clone(),
            unit: Unit::GainDb,
            threshold: Some(-70.0),
            penalty_band: None,
        };
        let annotation = Annotation {
            graph,
            scores: &scores,
            query: &query,
        };
        let Annotated::Yaml(text) = annotated(&annotation) else {
            panic!("YAML in, YAML out")
        };
        let back = rmf::parse_yaml(&text).unwrap();
        let (_, nodes, edges) = rmf::read(&back, None, "").unwrap();
        assert_eq!((&nodes, &edges), (&graph.nodes, &graph.edges));
        for (k, lane) in back["levels"]["L1"]["lanes"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            assert_eq!(
                lane[2]["irs_planner"]["worst_value"].as_f64(),
                scores[k].worst
            );
        }
        let office_report = report(&annotation);
        assert_eq!(
            office_report.closure_request["request"]["close_lanes"]
                .as_array()
                .unwrap()
                .len(),
            office_report.closed_edges.len()
        );
    }

    /// A roadmap of the warehouse, in both formats, attached to the scenario reads back to the
    /// same graph and scores the same; every edge is open at the threshold it was made at.
    #[test]
    fn roadmaps_attach_back_as_the_same_graph() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/warehouse");
        let base: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("warehouse.json")).unwrap())
                .unwrap();
        let scenario = Scenario::from_value_with_files(base.clone(), &dir).unwrap();
        let map = gain_map(&scenario);
        for format in [FormatName::Nav2Geojson, FormatName::RmfNavGraph] {
            let query = RoadmapQuery {
                spacing_m: 2.0,
                format,
                score: ScoreQuery {
                    map_id: map.id.clone(),
                    unit: Unit::GainDb,
                    threshold: Some(-75.0),
                    penalty_band: None,
                },
            };
            let graph = match roadmap(&map, &query).unwrap() {
                Annotated::GeoJson(v) => v,
                Annotated::Yaml(text) => rmf::parse_yaml(&text).unwrap(),
            };
            let mut doc = base.clone();
            doc["route_graph"] = json!({"format": format, "graph": graph});
            let attached = Scenario::from_value_with_files(doc, &dir).unwrap();
            let attached = attached.route_graph.as_ref().unwrap();
            assert!(attached.nodes.len() > 200, "{}", attached.nodes.len());
            let scores = score_edges(&map, &map.values, attached);
            assert!(scores.iter().all(|s| s.open_at(-75.0)), "{format:?}");
            let back = Annotation {
                graph: attached,
                scores: &scores,
                query: &query.score,
            };
            assert!(report(&back).closed_edges.is_empty());
        }
        let too_fine = RoadmapQuery {
            spacing_m: 0.1,
            format: FormatName::Nav2Geojson,
            score: ScoreQuery {
                map_id: map.id.clone(),
                unit: Unit::GainDb,
                threshold: None,
                penalty_band: None,
            },
        };
        assert_eq!(roadmap(&map, &too_fine).err().unwrap().field, "spacing_m");
    }

    /// A scenario file's `route_graph.file` is read beside it, its format from the extension
    /// (an Open-RMF YAML read as YAML), and refused naming the field when unreadable.
    #[test]
    fn graph_files_are_read_beside_the_scenario() {
        let read = |path: &Path, _: u64| -> std::io::Result<Vec<u8>> {
            match path.file_name().and_then(|n| n.to_str()) {
                Some("office.yaml") => Ok(RMF_OFFICE.as_bytes().to_vec()),
                Some("lanes.geojson") => Ok(NAV2_SAMPLE.as_bytes().to_vec()),
                _ => Err(std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "no such file",
                )),
            }
        };
        let mut doc = json!({"route_graph": {"file": "office.yaml"}});
        resolve_graph_reference(&mut doc, Path::new("/site"), &read).unwrap();
        assert_eq!(doc["route_graph"]["format"], "rmf_nav_graph");
        assert_eq!(
            doc["route_graph"]["graph"],
            rmf::parse_yaml(RMF_OFFICE).unwrap()
        );
        let mut doc = json!({"route_graph": {"file": "lanes.geojson"}});
        resolve_graph_reference(&mut doc, Path::new("/site"), &read).unwrap();
        assert_eq!(doc["route_graph"]["format"], "nav2_geojson");
        for (member, field) in [
            (json!({"file": "missing.geojson"}), "route_graph.file"),
            (json!({"file": "lanes.txt"}), "route_graph.file"),
            (
                json!({"file": "lanes.geojson", "graph": {}}),
                "route_graph.graph",
            ),
            (
                json!({"file": "lanes.txt", "format": "svg"}),
                "route_graph.format",
            ),
        ] {
            let mut doc = json!({ "route_graph": member });
            let e = resolve_graph_reference(&mut doc, Path::new("/site"), &read).unwrap_err();
            assert_eq!(e.field, field, "{e}");
        }
    }
}
