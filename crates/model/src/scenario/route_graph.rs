//! A route graph attached to a scenario: the nodes and directed edges a fleet's robots drive
//! along (a Nav2 route graph, an Open-RMF nav graph), in the scenario's frame.
//!
//! The model reads only the geometry: node positions and each edge's polyline. The graph as
//! its stack wrote it (ids, metadata, lane options) travels with it untouched in
//! [`GraphSource`], so the answers crate can write the same graph back with our scores added
//! where each stack keeps extra data; the formats themselves are the answers crate's.

use std::sync::Arc;

/// The format a route graph was written in (and is written back in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GraphFormat {
    /// A Nav2 Route Server GeoJSON graph (`nav2_route`).
    Nav2GeoJson,
    /// One level of an Open-RMF nav graph (`rmf_fleet_adapter`'s `parse_graph`).
    RmfNavGraph,
}

/// The graph as written: its format and its document (for Open-RMF, the YAML's data as JSON),
/// kept so that the scenario's canonical document, and so its id, hashes the graph the user
/// gave, and so that it can be written back annotated. The document is JSON text the model
/// never reads, as a floor plan's image is base64 it never reads: formats are the answers
/// crate's, and the model depends on no serialiser.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphSource {
    /// How `document` is laid out.
    pub format: GraphFormat,
    /// The Open-RMF level the graph was read from (`None` for Nav2).
    pub level: Option<String>,
    /// The document as JSON text (keys sorted, numbers round-tripping).
    pub document: Arc<str>,
}

/// A node: where it is, and the id its graph gives it.
#[derive(Debug, Clone, PartialEq)]
pub struct GraphNode {
    /// The node's id as its graph writes it (a Nav2 id, an Open-RMF vertex name or index).
    pub id: String,
    /// (x, y) in the scenario's frame (m).
    pub position: [f64; 2],
}

/// A directed edge from node `from` to node `to` (indices into [`RouteGraph::nodes`]).
#[derive(Debug, Clone, PartialEq)]
pub struct GraphEdge {
    /// The edge's id as its graph writes it (a Nav2 id, an Open-RMF lane index).
    pub id: String,
    /// The node it leaves.
    pub from: usize,
    /// The node it reaches.
    pub to: usize,
    /// The polyline a robot drives, from `from`'s position to `to`'s (at least those two; both
    /// formats read today drive straight, so exactly those two).
    pub points: Vec<[f64; 2]>,
}

impl GraphEdge {
    /// The polyline's length (m).
    pub fn length_m(&self) -> f64 {
        self.points
            .windows(2)
            .map(|p| (p[1][0] - p[0][0]).hypot(p[1][1] - p[0][1]))
            .sum()
    }
}

/// A route graph: nodes, directed edges, and the document they came from.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteGraph {
    /// The nodes, in the order the graph lists them.
    pub nodes: Vec<GraphNode>,
    /// The edges, in the order the graph lists them.
    pub edges: Vec<GraphEdge>,
    /// The graph as written.
    pub source: Arc<GraphSource>,
}

/// Most nodes a route graph may have (a site's graph has hundreds to thousands).
pub const MAX_GRAPH_NODES: usize = 100_000;
/// Most edges a route graph may have.
pub const MAX_GRAPH_EDGES: usize = 200_000;

impl RouteGraph {
    /// The node nearest to `p` (ties to the lower index); `None` for a graph without nodes.
    pub fn nearest_node(&self, p: [f64; 2]) -> Option<usize> {
        let mut best: Option<(f64, usize)> = None;
        for (k, n) in self.nodes.iter().enumerate() {
            let d = (n.position[0] - p[0]).hypot(n.position[1] - p[1]);
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, k));
            }
        }
        best.map(|(_, k)| k)
    }
}
