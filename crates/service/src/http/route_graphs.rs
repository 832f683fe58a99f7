//! `/v1/maps/{map_id}/route-graph`: the scenario's route graph scored on the map — our JSON
//! report, or the graph in its own format (Nav2 GeoJSON, Open-RMF nav graph YAML) with the
//! scores written where its stack keeps extra data; and `/v1/maps/{map_id}/roadmap`, a route
//! graph made from the map for a site that has none.

use super::problem::ApiError;
use super::{heavy, only_query};
use crate::app::App;
use crate::app::Error;
use crate::app::identity::Caller;
use crate::ids::MapId;
use axum::Json;
use axum::extract::{Path, Query, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use irs_answers::route_graph::{
    self, Annotated, FormatName, GraphOutput, RoadmapQuery, ScoreQuery, Scored,
};
use irs_model::input::{parse_finite, parse_name};
use irs_model::radiomap::Unit;
use std::collections::HashMap;

/// The media type of a Nav2 route graph.
const GEOJSON: &str = "application/geo+json";
/// The media type of an Open-RMF nav graph.
const YAML: &str = "application/yaml";

pub(super) async fn route_graph(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(&query, &["threshold", "unit", "penalty_band", "format"])?;
    let number = |name: &'static str| {
        query
            .get(name)
            .map(|text| parse_finite(text).map_err(|e| Error::invalid(name, e)))
            .transpose()
    };
    let (threshold, penalty_band) = (number("threshold")?, number("penalty_band")?);
    let unit = query
        .get("unit")
        .map(|text| text.parse::<Unit>().map_err(|e| Error::invalid("unit", e)))
        .transpose()?;
    let output = query
        .get("format")
        .map(|text| {
            text.parse::<GraphOutput>()
                .map_err(|e| Error::invalid("format", e))
        })
        .transpose()?
        .unwrap_or_default();
    let (map, scenario) = state.map_with_scenario(&caller, &map_id).await?;
    let score_query = ScoreQuery {
        map_id: map_id.to_string(),
        unit: unit.unwrap_or(map.native_unit()),
        threshold,
        penalty_band,
    };
    let edges = scenario.route_graph.as_ref().map_or(0, |g| g.edges.len());
    let work = map.grid.cells().saturating_add(edges.saturating_mul(64));
    let scored = heavy(&state, "route graph", work, move |_| {
        route_graph::score(&scenario, &map, &score_query, output)
    })
    .await??;
    Ok(match scored {
        Scored::Report(report) => Json(report).into_response(),
        Scored::Graph(Annotated::GeoJson(graph)) => {
            ([(header::CONTENT_TYPE, GEOJSON)], Json(graph)).into_response()
        }
        Scored::Graph(Annotated::Yaml(text)) => {
            ([(header::CONTENT_TYPE, YAML)], text).into_response()
        }
    })
}

/// A roadmap of the map's free (or, at `threshold`, feasible) region as a route graph.
pub(super) async fn roadmap(
    State(state): State<App>,
    caller: Caller,
    Path(map_id): Path<MapId>,
    Query(query): Query<HashMap<String, String>>,
) -> Result<Response, ApiError> {
    only_query(
        &query,
        &["spacing_m", "threshold", "unit", "penalty_band", "format"],
    )?;
    let number = |name: &'static str| {
        query
            .get(name)
            .map(|text| parse_finite(text).map_err(|e| Error::invalid(name, e)))
            .transpose()
    };
    let spacing_m = number("spacing_m")?
        .ok_or_else(|| Error::invalid("spacing_m", "the spacing_m query parameter is required"))?;
    let (threshold, penalty_band) = (number("threshold")?, number("penalty_band")?);
    let unit = query
        .get("unit")
        .map(|text| text.parse::<Unit>().map_err(|e| Error::invalid("unit", e)))
        .transpose()?;
    let format = query
        .get("format")
        .map(|text| {
            parse_name::<FormatName>(text)
                .map_err(|_| Error::invalid("format", "expected nav2_geojson or rmf_nav_graph"))
        })
        .transpose()?
        .unwrap_or(FormatName::Nav2Geojson);
    let map = state.map(&caller, &map_id).await?;
    let request = RoadmapQuery {
        spacing_m,
        format,
        score: ScoreQuery {
            map_id: map_id.to_string(),
            unit: unit.unwrap_or(map.native_unit()),
            threshold,
            penalty_band,
        },
    };
    let cells = map.grid.cells();
    let graph = heavy(&state, "roadmap", cells.saturating_mul(4), move |_| {
        route_graph::roadmap(&map, &request)
    })
    .await??;
    Ok(match graph {
        Annotated::GeoJson(graph) => {
            ([(header::CONTENT_TYPE, GEOJSON)], Json(graph)).into_response()
        }
        Annotated::Yaml(text) => ([(header::CONTENT_TYPE, YAML)], text).into_response(),
    })
}
