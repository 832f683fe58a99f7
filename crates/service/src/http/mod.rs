//! The HTTP layer: the route table (the contract is `openapi.yaml`) and one module per resource
//! ([`scenarios`], [`maps`], [`paths`] with sweeps and coverage, [`exports`], [`route_graphs`], [`jobs`],
//! [`placements`], [`ops`] for health, readiness, version and metrics). A handler parses its
//! request, calls the application and renders the answer; all physics lives in the library
//! crates. Also here: the JSON body extractor, listings' pages, problem+json answers
//! ([`problem`], where the application's errors become problems) and authentication at the door
//! ([`auth`]).

pub(crate) mod auth;
pub(crate) mod delivery;
mod exports;
mod fleet;
mod jobs;
pub(crate) mod json;
mod maps;
mod ops;
mod paths;
mod placements;
pub(crate) mod problem;
mod route_graphs;
mod scenarios;

use crate::app::App;
use crate::app::Error;
use crate::app::jobs::JobView;
use axum::extract::{DefaultBodyLimit, MatchedPath, State};
use axum::extract::{FromRequest, Request};
use axum::http::{HeaderValue, Method};
use axum::http::{StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{MethodRouter, delete, get, post};
use axum::{Json, Router};
use irs_model::radiomap::Progress;
use problem::{ApiError, parse_json};
use std::collections::HashMap;
use std::time::{Duration, Instant};
use tower::ServiceBuilder;
use tower_http::LatencyUnit;
use tower_http::compression::CompressionLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::trace::{DefaultOnResponse, TraceLayer};

/// Every route: path, methods, handler. The router is built from this table and a test checks
/// it against `openapi.yaml`.
pub fn route_table() -> Vec<(&'static str, &'static [&'static str], MethodRouter<App>)> {
    vec![
        ("/", &["get"], get(crate::viewer::index)),
        ("/viewer/viewer.js", &["get"], get(crate::viewer::script)),
        ("/viewer/viewer.css", &["get"], get(crate::viewer::style)),
        ("/healthz", &["get"], get(ops::healthz)),
        ("/readyz", &["get"], get(ops::readyz)),
        ("/version", &["get"], get(ops::version)),
        ("/metrics", &["get"], get(ops::metrics_text)),
        (
            "/v1/scenarios",
            &["get", "post"],
            get(scenarios::list_scenarios).post(scenarios::register_scenario),
        ),
        (
            "/v1/scenarios/{scenario_id}",
            &["get", "delete"],
            get(scenarios::get_scenario).delete(scenarios::delete_scenario),
        ),
        (
            "/v1/maps",
            &["get", "post"],
            get(maps::list_maps).post(maps::request_map),
        ),
        (
            "/v1/maps/{map_id}",
            &["get", "delete"],
            get(maps::get_map).delete(maps::delete_map),
        ),
        ("/v1/maps/{map_id}/coverage", &["get"], get(paths::coverage)),
        ("/v1/maps/{map_id}/image.png", &["get"], get(exports::image)),
        (
            "/v1/maps/{map_id}/nav2-mask",
            &["get"],
            get(exports::nav2_mask),
        ),
        (
            "/v1/maps/{map_id}/values.npy",
            &["get"],
            get(exports::values_npy),
        ),
        (
            "/v1/maps/{map_id}/zone-set",
            &["get"],
            get(exports::zone_set),
        ),
        (
            "/v1/maps/{map_id}/route-graph",
            &["get"],
            get(route_graphs::route_graph),
        ),
        (
            "/v1/maps/{map_id}/roadmap",
            &["get"],
            get(route_graphs::roadmap),
        ),
        ("/v1/jobs", &["get"], get(jobs::list_jobs)),
        (
            "/v1/jobs/{job_id}",
            &["get", "delete"],
            get(jobs::get_job).merge(delete(jobs::cancel_job)),
        ),
        ("/v1/placements", &["post"], post(placements::place)),
        (
            "/v1/placements/{placement_id}",
            &["get"],
            get(placements::get_placement),
        ),
        ("/v1/paths", &["post"], post(paths::plan_path)),
        ("/v1/fleet-plans", &["post"], post(fleet::plan_fleet)),
        (
            "/v1/fleet-plans/{plan_id}",
            &["get"],
            get(fleet::get_fleet_plan),
        ),
        ("/v1/checks/{check_id}", &["get"], get(paths::get_check)),
        ("/v1/sweeps", &["post"], post(paths::sweep)),
    ]
}

/// Every route of the API, the viewer and the operations endpoints, without the middleware.
pub fn router() -> Router<App> {
    route_table()
        .into_iter()
        .fold(Router::new(), |r, (path, _, handler)| {
            r.route(path, handler)
        })
}

/// The JSON body extractor of this API: strict parsing, problem+json on every failure, and the
/// configured body limit named in the 413. A large body is parsed on the query pool, not on the
/// async thread that read it (`app::queries::INLINE_BYTES`).
pub(crate) struct Body<T>(pub T);

impl<T: serde::de::DeserializeOwned + Send + 'static> FromRequest<App> for Body<T> {
    type Rejection = ApiError;

    async fn from_request(req: Request, state: &App) -> Result<Self, ApiError> {
        let Some(ct) = req.headers().get(header::CONTENT_TYPE) else {
            return Err(ApiError::unsupported_media_type(
                "the body must be JSON: send Content-Type: application/json",
            ));
        };
        let ct = ct.to_str().unwrap_or("");
        let essence = ct
            .split(';')
            .next()
            .unwrap_or("")
            .trim()
            .to_ascii_lowercase();
        if essence != "application/json" && !essence.ends_with("+json") {
            return Err(ApiError::unsupported_media_type(format!(
                "expected application/json, got {ct:?}"
            )));
        }
        // Registration carries floor plans: its own, larger limit; the layer's limit is the
        // larger of the two, so every other route is held to its own here, by its declared
        // length before reading and by what arrived after.
        let limit = if req.method() == Method::POST && req.uri().path() == "/v1/scenarios" {
            state.limits().max_scenario_body_bytes
        } else {
            state.limits().max_body_bytes
        };
        let declared = req
            .headers()
            .get(header::CONTENT_LENGTH)
            .and_then(|v| v.to_str().ok()?.parse::<u64>().ok());
        if declared.is_some_and(|n| n > limit as u64) {
            return Err(ApiError::body_too_large(limit as u64));
        }
        let timeout = state.limits().body_timeout;
        let read = axum::body::Bytes::from_request(req, state);
        let bytes = tokio::time::timeout(timeout, read)
            .await
            .map_err(|_| ApiError::body_timeout(timeout.as_secs()))?
            .map_err(|rejection| {
                if rejection.status() == StatusCode::PAYLOAD_TOO_LARGE {
                    ApiError::body_too_large(limit as u64)
                } else {
                    ApiError::malformed_json(rejection.body_text())
                }
            })?;
        if bytes.len() > limit {
            return Err(ApiError::body_too_large(limit as u64));
        }
        let parsed = state
            .queries()
            .run_sized("body", bytes.len(), move || parse_json(&bytes))
            .await?;
        parsed.map(Body)
    }
}

/// Items per page of a listing when the client does not say, and at most.
const DEFAULT_PAGE: usize = 100;
const MAX_PAGE: usize = 1000;

/// A listing's `limit` and `cursor` query parameters (the cursor is the `next_cursor` of the
/// page before: the key of its last item).
struct Page {
    limit: usize,
    cursor: Option<String>,
}

impl Page {
    fn of(query: &HashMap<String, String>) -> Result<Page, Error> {
        only_query(query, &["limit", "cursor"])?;
        let limit = match query.get("limit") {
            None => DEFAULT_PAGE,
            Some(text) => text
                .parse::<usize>()
                .ok()
                .filter(|n| (1..=MAX_PAGE).contains(n))
                .ok_or_else(|| {
                    Error::limit_exceeded(
                        "limit",
                        MAX_PAGE as u64,
                        format!("must be a whole number from 1 to {MAX_PAGE}"),
                    )
                })?,
        };
        let cursor = query.get("cursor").cloned();
        if let Some(c) = &cursor
            && (c.is_empty() || c.len() > 128 || !c.bytes().all(|b| b.is_ascii_alphanumeric()))
        {
            return Err(Error::invalid(
                "cursor",
                "not a cursor this server gave: use a listing's next_cursor",
            ));
        }
        Ok(Page { limit, cursor })
    }

    /// The page of `items` (in listing order, each with its key) after the cursor, and the
    /// cursor of the next page if there is one. `after(key, cursor)` tells whether an item
    /// comes after the cursor in listing order.
    fn cut<T>(
        &self,
        items: Vec<(String, T)>,
        after: impl Fn(&str, &str) -> bool,
    ) -> (Vec<T>, Option<String>) {
        let mut rest = items
            .into_iter()
            .filter(|(key, _)| self.cursor.as_deref().is_none_or(|c| after(key, c)));
        let page: Vec<(String, T)> = rest.by_ref().take(self.limit).collect();
        let next = match rest.next() {
            Some(_) => page.last().map(|(key, _)| key.clone()),
            None => None,
        };
        (page.into_iter().map(|(_, item)| item).collect(), next)
    }
}

fn accepted(view: JobView) -> Response {
    let location = view.job_id.href();
    (
        StatusCode::ACCEPTED,
        [(header::LOCATION, location)],
        Json(view),
    )
        .into_response()
}

/// Work on a map with more cells than this (path and sweep searches, map bodies, exports) is a
/// heavy query, run on the query pool under its admission control (`app::queries`). A
/// search or a serialisation touches every cell at a few tens of nanoseconds each, so past
/// ~10 000 cells it would hold an async worker thread for longer than the ~0.1–1 ms tokio
/// budgets between awaits, and every other request on that thread (health checks included)
/// would wait. Below it (the paper's map has 1 681 cells) the work is cheaper than the
/// hand-off to another thread.
const INLINE_WORK_CELLS: usize = 10_000;

/// Runs `work` inline for small maps and as a heavy query for big ones (see
/// [`INLINE_WORK_CELLS`]); the work's [`Progress`] is cancelled if the client goes.
async fn heavy<T: Send + 'static>(
    state: &App,
    what: &'static str,
    cells: usize,
    work: impl FnOnce(&Progress) -> T + Send + 'static,
) -> Result<T, Error> {
    if cells <= INLINE_WORK_CELLS {
        return Ok(work(&Progress::default()));
    }
    state.queries().run(what, work).await
}

/// Rejects query parameters outside `allowed`, naming the first unknown one.
fn only_query(query: &HashMap<String, String>, allowed: &[&str]) -> Result<(), Error> {
    match query.keys().find(|k| !allowed.contains(&k.as_str())) {
        Some(unknown) => Err(Error::invalid(unknown.clone(), "unknown query parameter")),
        None => Ok(()),
    }
}

/// Longest `x-request-id` taken from a client (a UUID is 36 characters); a longer one, or one
/// with characters outside `[A-Za-z0-9._:-]`, is replaced by a fresh UUID so logs stay clean.
const MAX_REQUEST_ID_CHARS: usize = 64;

/// Longest request URI (path and query, bytes) the service reads: 8 KiB, the common limit of
/// proxies and browsers, holds every URI of this API with room to spare (the longest are a
/// listing's cursor of 128 characters and a coverage query's few numbers). A longer one gets
/// 414 as problem+json; hyper's own limit (64 KiB) would answer 414 with an empty body.
pub(crate) const MAX_URI_BYTES: usize = 8 * 1024;

/// The origins CORS allows (`--cors-origin`), checked: each an http(s) origin that is a
/// valid header value.
pub(crate) fn cors_origins(origins: &[String]) -> Result<Vec<HeaderValue>, String> {
    origins
        .iter()
        .map(|o| {
            HeaderValue::from_str(o.trim())
                .ok()
                .filter(|_| o.starts_with("http://") || o.starts_with("https://"))
                .ok_or_else(|| format!("--cors-origin {o:?}: not an http(s) origin"))
        })
        .collect()
}

/// The full application: routes, fallbacks, metrics, authentication, the request timeout,
/// request ids, tracing, CORS (only when origins are configured: none, no CORS headers at all),
/// the body limit and the answers' delivery under `answers` ([`delivery`]).
pub(crate) fn app(
    state: App,
    cors_origins: Vec<HeaderValue>,
    answers: delivery::Budget,
) -> axum::Router {
    let max_body = state
        .limits()
        .max_body_bytes
        .max(state.limits().max_scenario_body_bytes);
    let cors = (!cors_origins.is_empty()).then(|| {
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(cors_origins))
            .allow_methods([Method::GET, Method::POST, Method::DELETE])
            .allow_headers([header::CONTENT_TYPE, header::AUTHORIZATION, header::ACCEPT])
            .expose_headers([header::LOCATION, header::RETRY_AFTER])
            .max_age(Duration::from_secs(600))
    });
    let router = router()
        .route_layer(middleware::from_fn(track_metrics))
        .fallback(route_not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(DefaultBodyLimit::max(max_body))
        .layer(middleware::from_fn_with_state(state.clone(), auth::authenticate))
        .layer(middleware::from_fn_with_state(state.clone(), request_timeout))
        // Inside compression, so answers are weighed as built (see `delivery`).
        .layer(middleware::from_fn_with_state(answers, delivery::deliver))
        // gzip or brotli when the client accepts it (a 577k-cell map body is 10.9 MB of JSON);
        // tower-http's default predicate leaves PNGs and tiny bodies alone.
        .layer(CompressionLayer::new())
        .layer(
            ServiceBuilder::new()
                .layer(middleware::from_fn(clean_request_id))
                .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
                // The access log: one line at info per answer ("finished processing request",
                // with the status and the latency) in the request's span, which names the
                // method, the URI, the route template (set by `track_metrics` once routed) and
                // the request id.
                .layer(
                    TraceLayer::new_for_http()
                        .make_span_with(|req: &Request| {
                            let request_id = req.headers().get("x-request-id").and_then(|v| v.to_str().ok()).unwrap_or("-");
                            tracing::info_span!("request", method = %req.method(), uri = %req.uri(), route = tracing::field::Empty, request_id = %request_id)
                        })
                        .on_response(
                            DefaultOnResponse::new()
                                .level(tracing::Level::INFO)
                                .latency_unit(LatencyUnit::Micros),
                        ),
                )
                .layer(PropagateRequestIdLayer::x_request_id())
                .layer(middleware::from_fn(refuse_long_uri)),
        );
    let router = match cors {
        Some(cors) => router.layer(cors),
        None => router,
    };
    router.with_state(state)
}

/// Drops a client's `x-request-id` that is too long or has characters that do not belong in a
/// log line; [`SetRequestIdLayer`] then gives the request a fresh UUID.
async fn clean_request_id(mut req: Request, next: Next) -> Response {
    let acceptable = |v: &HeaderValue| {
        let bytes = v.as_bytes();
        !bytes.is_empty()
            && bytes.len() <= MAX_REQUEST_ID_CHARS
            && bytes
                .iter()
                .all(|b| b.is_ascii_alphanumeric() || b"._:-".contains(b))
    };
    if req
        .headers()
        .get("x-request-id")
        .is_some_and(|v| !acceptable(v))
    {
        req.headers_mut().remove("x-request-id");
    }
    next.run(req).await
}

/// Answers 414 (problem+json) to a request whose URI is longer than [`MAX_URI_BYTES`], before
/// authentication and routing look at it.
async fn refuse_long_uri(req: Request, next: Next) -> Response {
    let uri = req.uri();
    let length = uri.authority().map_or(0, |a| a.as_str().len())
        + uri.path_and_query().map_or(0, |pq| pq.as_str().len());
    if length > MAX_URI_BYTES {
        return ApiError::uri_too_long(length, MAX_URI_BYTES).into_response();
    }
    next.run(req).await
}

/// Answers 503 when a request takes longer than the request timeout (the handler's future is
/// dropped, which cancels its heavy query, see `queries`).
async fn request_timeout(State(state): State<App>, req: Request, next: Next) -> Response {
    let limit = state.limits().request_timeout;
    match tokio::time::timeout(limit, next.run(req)).await {
        Ok(response) => response,
        Err(_) => {
            metrics::counter!("irs_request_timeouts_total").increment(1);
            ApiError::request_timeout(limit.as_secs()).into_response()
        }
    }
}

async fn route_not_found(State(_): State<App>, req: Request) -> Response {
    metrics::counter!("http_requests_total", "route" => "unmatched", "method" => req.method().to_string(), "status" => "404").increment(1);
    ApiError::route_not_found(req.uri().path()).into_response()
}

async fn method_not_allowed() -> Response {
    ApiError::method_not_allowed().into_response()
}

async fn track_metrics(req: Request, next: Next) -> Response {
    let started = Instant::now();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or("unmatched".to_string(), |m| m.as_str().to_string());
    tracing::Span::current().record("route", route.as_str());
    let method = req.method().to_string();
    let response = next.run(req).await;
    let status = response.status().as_u16().to_string();
    metrics::counter!("http_requests_total", "route" => route.clone(), "method" => method, "status" => status).increment(1);
    metrics::histogram!("http_request_duration_seconds", "route" => route)
        .record(started.elapsed().as_secs_f64());
    response
}
