//! The `graph` and `roadmap` commands: the scenario's route graph scored on its map, as our
//! JSON report or as the graph in its own format with the scores added (`GET
//! /v1/maps/{map_id}/route-graph`); a route graph made from the map (`GET
//! /v1/maps/{map_id}/roadmap`).

use super::{Failure, MapArgs, build_map, flag, load_scenario, print_json, print_text};
use clap::Args;
use irs_answers::route_graph::{
    self, Annotated, FormatName, GraphOutput, RoadmapQuery, ScoreQuery, Scored,
};
use irs_model::input::{parse_finite, parse_name};
use irs_model::radiomap::Unit;

#[derive(Debug, Args)]
pub struct GraphArgs {
    #[command(flatten)]
    pub map: MapArgs,
    /// QoS threshold in --unit: edges meeting a cell below it are closed; without it every
    /// edge is scored and none is closed for the radio's sake.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub threshold: Option<f64>,
    /// The unit of the scores, the threshold and the band: gain_db, dbm, snr_db, bps_hz or mbps;
    /// default: the map's own.
    #[arg(long, value_name = "UNIT")]
    pub unit: Option<Unit>,
    /// Width of the band above the threshold whose open edges get a penalty in (0, 1] (Nav2's
    /// PenaltyScorer reads it); only with --threshold.
    #[arg(long, value_name = "VALUE", value_parser = parse_finite)]
    pub penalty_band: Option<f64>,
    /// report (our JSON, with the closures as the graph's stack takes them) or graph (the
    /// Nav2 GeoJSON or Open-RMF YAML as given, annotated).
    #[arg(long, value_name = "FORMAT", default_value = "report")]
    pub format: GraphOutput,
}

/// `irs-planner graph …`.
pub fn run_graph(args: &GraphArgs) -> Result<(), Failure> {
    let query = |map_id: String, unit| ScoreQuery {
        map_id,
        unit,
        threshold: args.threshold,
        penalty_band: args.penalty_band,
    };
    query(String::new(), Unit::GainDb)
        .validate()
        .map_err(|e| Failure::input(flag(&e)))?;
    let scenario = load_scenario(&args.map.source)?;
    if scenario.route_graph.is_none() {
        return Err(Failure::input(
            "--scenario: the scenario has no route_graph to score",
        ));
    }
    let map = build_map(&args.map, &scenario)?;
    let query = query(map.id.clone(), args.unit.unwrap_or(map.native_unit()));
    match route_graph::score(&scenario, &map, &query, args.format)
        .map_err(|e| Failure::input(flag(&e)))?
    {
        Scored::Report(report) => print_json(&report),
        Scored::Graph(graph) => print_graph(graph),
    }
}

fn print_graph(graph: Annotated) -> Result<(), Failure> {
    match graph {
        Annotated::GeoJson(graph) => print_json(&graph),
        Annotated::Yaml(text) => print_text(text.as_bytes()),
    }
}

#[derive(Debug, Args)]
pub struct RoadmapArgs {
    #[command(flatten)]
    pub map: MapArgs,
    /// Distance between neighbouring nodes along x and y (m), rounded to whole cells.
    #[arg(long, value_name = "METRES", value_parser = parse_finite)]
    pub spacing_m: f64,
    /// Map only the region meeting this threshold (in --unit); without it, the free region.
    #[arg(long, allow_hyphen_values = true, value_parser = parse_finite)]
    pub threshold: Option<f64>,
    /// The unit of the scores and the threshold; default: the map's own.
    #[arg(long, value_name = "UNIT")]
    pub unit: Option<Unit>,
    /// Width of the band above the threshold whose edges get a penalty in (0, 1]; only with
    /// --threshold.
    #[arg(long, value_name = "VALUE", value_parser = parse_finite)]
    pub penalty_band: Option<f64>,
    /// nav2_geojson (a Nav2 Route Server graph) or rmf_nav_graph (an Open-RMF nav graph).
    #[arg(long, value_name = "FORMAT", default_value = "nav2_geojson", value_parser = parse_name::<FormatName>)]
    pub format: FormatName,
}

/// `irs-planner roadmap …`: the graph, scored, in its format.
pub fn run_roadmap(args: &RoadmapArgs) -> Result<(), Failure> {
    let scenario = load_scenario(&args.map.source)?;
    let map = build_map(&args.map, &scenario)?;
    let query = RoadmapQuery {
        spacing_m: args.spacing_m,
        format: args.format,
        score: ScoreQuery {
            map_id: map.id.clone(),
            unit: args.unit.unwrap_or(map.native_unit()),
            threshold: args.threshold,
            penalty_band: args.penalty_band,
        },
    };
    let graph = route_graph::roadmap(&map, &query).map_err(|e| Failure::input(flag(&e)))?;
    print_graph(graph)
}
