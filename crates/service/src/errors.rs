//! Every 4xx/5xx answer as RFC 9457 `application/problem+json`: a machine `type` and `code`, a
//! `title`, the `status`, a human `detail`, and the offending `field` (and `limit`) where there
//! is one. [`parse_json`] backs the API's JSON extractor so malformed bodies, unknown fields and
//! oversized bodies get the same treatment.

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use irs_model::input::FieldError;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// The body of every error answer (RFC 9457).
#[derive(Debug, Clone, Serialize)]
pub struct Problem {
    #[serde(rename = "type")]
    pub kind: String,
    pub code: &'static str,
    pub title: &'static str,
    pub status: u16,
    pub detail: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub job_id: Option<String>,
}

/// An error answer; build with the constructors below.
#[derive(Debug, Clone)]
pub struct ApiError {
    pub problem: Box<Problem>,
    pub retry_after_s: Option<u64>,
}

impl ApiError {
    fn new(
        status: StatusCode,
        code: &'static str,
        title: &'static str,
        detail: impl Into<String>,
    ) -> Self {
        ApiError {
            problem: Box::new(Problem {
                kind: format!("https://irs-planner.dev/problems/{code}"),
                code,
                title,
                status: status.as_u16(),
                detail: detail.into(),
                field: None,
                limit: None,
                job_id: None,
            }),
            retry_after_s: None,
        }
    }
    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        self.problem.field = Some(field.into());
        self
    }
    pub fn with_limit(mut self, limit: u64) -> Self {
        self.problem.limit = Some(limit);
        self
    }

    pub fn malformed_json(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::BAD_REQUEST,
            "malformed_json",
            "Malformed JSON body",
            detail,
        )
    }
    pub fn invalid(field: impl Into<String>, detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_field",
            "Invalid field",
            detail,
        )
        .with_field(field)
    }
    /// A scenario document that failed validation (its own problem code, so clients can tell a
    /// bad floor from a bad request parameter).
    pub fn invalid_scenario(error: FieldError) -> Self {
        let detail = error.to_string();
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "invalid_scenario",
            "Invalid scenario",
            detail,
        )
        .with_field(error.field)
    }
    pub fn limit_exceeded(field: impl Into<String>, limit: u64, detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "limit_exceeded",
            "Limit exceeded",
            detail,
        )
        .with_field(field)
        .with_limit(limit)
    }
    pub fn body_too_large(limit: u64) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "body_too_large",
            "Request body too large",
            format!("the request body exceeds the limit of {limit} bytes"),
        )
        .with_limit(limit)
    }
    pub fn unsupported_media_type(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            "Unsupported media type",
            detail,
        )
    }
    pub fn not_found(what: &'static str, id: &str) -> Self {
        Self::new(
            StatusCode::NOT_FOUND,
            "not_found",
            "Not found",
            format!("no {what} with id {id:?}"),
        )
    }
    pub fn route_not_found(path: &str) -> Self {
        Self::new(
            StatusCode::NOT_FOUND,
            "route_not_found",
            "Route not found",
            format!("no route for {path}"),
        )
    }
    pub fn method_not_allowed() -> Self {
        Self::new(
            StatusCode::METHOD_NOT_ALLOWED,
            "method_not_allowed",
            "Method not allowed",
            "this route does not take that method",
        )
    }
    pub fn map_not_ready(map_id: &str, job_id: &str) -> Self {
        let mut e = Self::new(
            StatusCode::CONFLICT,
            "map_not_ready",
            "Map not ready",
            format!("map {map_id} is being built by job {job_id}; poll /v1/jobs/{job_id}"),
        );
        e.problem.job_id = Some(job_id.to_string());
        e
    }
    pub fn placement_not_ready(job_id: &str) -> Self {
        let mut e = Self::new(
            StatusCode::CONFLICT,
            "placement_not_ready",
            "Placement not ready",
            format!("placement {job_id} is still running; poll /v1/jobs/{job_id}"),
        );
        e.problem.job_id = Some(job_id.to_string());
        e
    }
    pub fn scenario_protected(id: &str, source: &str) -> Self {
        Self::new(
            StatusCode::CONFLICT,
            "scenario_protected",
            "Scenario is part of the configuration",
            format!(
                "scenario {id} comes from the server's {source} scenarios and cannot be deleted"
            ),
        )
    }
    pub fn scenario_in_use(id: &str, job_id: &str) -> Self {
        let mut e = Self::new(
            StatusCode::CONFLICT,
            "scenario_in_use",
            "Scenario in use",
            format!("job {job_id} is building a map of scenario {id}; cancel it or wait"),
        );
        e.problem.job_id = Some(job_id.to_string());
        e
    }
    pub fn job_finished(job_id: &str, state: &str) -> Self {
        Self::new(
            StatusCode::CONFLICT,
            "job_finished",
            "Job already finished",
            format!("job {job_id} is already {state}"),
        )
    }
    pub fn internal(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "internal_error",
            "Internal error",
            detail,
        )
    }
    pub fn build_failed(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "build_failed",
            "Map build failed",
            detail,
        )
    }
    pub fn queue_full(limit: usize) -> Self {
        let mut e = Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "queue_full",
            "Job queue full",
            format!("{limit} map builds are already waiting for a worker; retry later"),
        )
        .with_limit(limit as u64);
        e.retry_after_s = Some(5);
        e
    }
    pub fn registry_full(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::INSUFFICIENT_STORAGE,
            "registry_full",
            "Scenario registry full",
            detail,
        )
    }
    /// Heavy queries are all taken and `limit` more wait: come back in `retry_after_s`.
    pub fn busy(what: &str, limit: usize, retry_after_s: u64) -> Self {
        let mut e = Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "busy",
            "Server busy",
            format!(
                "every query worker is busy and {limit} heavy queries already wait; this {what} \
                 was not started: retry later"
            ),
        )
        .with_limit(limit as u64);
        e.retry_after_s = Some(retry_after_s);
        e
    }
    pub fn unauthorized(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNAUTHORIZED,
            "unauthorized",
            "Unauthorized",
            detail,
        )
    }
    /// The request as a whole took longer than the server's request timeout.
    pub fn request_timeout(seconds: u64) -> Self {
        let mut e = Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "request_timeout",
            "Request timed out",
            format!(
                "the request was not answered within the server's limit of {seconds} s; long \
                 builds run as jobs, so retry, or ask for the map and poll its job"
            ),
        )
        .with_limit(seconds);
        e.retry_after_s = Some(1);
        e
    }
    /// The shared store (Redis, `--redis-url`) cannot be used now; the replica retries by itself.
    pub fn store_unavailable(detail: impl Into<String>) -> Self {
        let mut e = Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "store_unavailable",
            "Shared store unavailable",
            format!(
                "{}; maps this replica holds still answer, everything else needs the shared store: retry shortly",
                detail.into()
            ),
        );
        e.retry_after_s = Some(1);
        e
    }
    /// The client did not send its body within the body timeout.
    pub fn body_timeout(seconds: u64) -> Self {
        Self::new(
            StatusCode::REQUEST_TIMEOUT,
            "body_timeout",
            "Request body timed out",
            format!("the request body did not arrive within {seconds} s"),
        )
        .with_limit(seconds)
    }
    pub fn not_ready() -> Self {
        Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "not_ready",
            "Not ready",
            "the service is starting or shutting down",
        )
    }
    pub fn status(&self) -> StatusCode {
        StatusCode::from_u16(self.problem.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR)
    }
}

/// A request field the engine rejected: 422 `invalid_field` naming it.
impl From<FieldError> for ApiError {
    fn from(error: FieldError) -> Self {
        ApiError::invalid(error.field, error.reason)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let status = self.status();
        let body = serde_json::to_vec(&self.problem).unwrap_or_default();
        let mut response = (status, body).into_response();
        let headers = response.headers_mut();
        headers.insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/problem+json"),
        );
        if let Some(s) = self.retry_after_s {
            headers.insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        if status == StatusCode::UNAUTHORIZED {
            headers.insert(
                header::WWW_AUTHENTICATE,
                HeaderValue::from_static("Bearer realm=\"irs-planner\""),
            );
        }
        response
    }
}

/// Parses a JSON body strictly, mapping serde errors to problems that name the field. The text
/// is parsed as JSON first (a syntax error is 400), then the value is matched to `T` (every
/// mismatch is 422 naming the field, including arrays of the wrong length, which serde_json's
/// streaming parser would report as trailing characters, a syntax error).
///
/// A body that `T` reads straight from the text is taken as read: building the `Value` first
/// was a twentieth of a repeated path query's time, and a body the streaming parser accepts
/// reads the same through a `Value`. Only a body it refuses (or would read differently, such
/// as one with a repeated key, which it refuses) goes the slower way, for its error or value.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    if let Ok(parsed) = serde_json::from_slice(bytes) {
        return Ok(parsed);
    }
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| ApiError::malformed_json(e.to_string()))?;
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = e.path().to_string();
        ApiError::invalid(
            if path == "." { "$".to_string() } else { path },
            e.into_inner().to_string(),
        )
    })
}
