//! Every 4xx/5xx answer as RFC 9457 `application/problem+json`: a machine `type` and `code`, a
//! `title`, the `status`, a human `detail`, and the offending `field` (and `limit`) where there
//! is one. The application's errors ([`app::Error`]) become problems here and only here; the
//! errors of the transport itself (a malformed or oversized body, an unknown route, a request
//! timeout) are built here directly. [`parse_json`] backs the API's JSON extractor so malformed
//! bodies, unknown fields and oversized bodies get the same treatment.

use crate::app;
use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use irs_model::input::FieldError;
use serde::Serialize;
use serde::de::DeserializeOwned;

/// The body of every error answer (RFC 9457).
#[derive(Debug, Clone, Serialize)]
pub struct Problem {
    /// A URI naming the kind of problem (`type`).
    #[serde(rename = "type")]
    pub kind: String,
    /// The stable machine-readable code clients branch on.
    pub code: &'static str,
    /// A short summary of the kind of problem.
    pub title: &'static str,
    /// The HTTP status, repeated in the body.
    pub status: u16,
    /// What went wrong with this request, and what to do about it.
    pub detail: String,
    /// The request's JSON path (or query parameter) at fault, when one is.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The limit that was exceeded, in the unit `detail` names.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit: Option<u64>,
    /// The job concerned (a map not ready yet, a scenario in use).
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
    fn with_job(mut self, job_id: crate::ids::JobId) -> Self {
        self.problem.job_id = Some(job_id.to_string());
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
    pub fn body_too_large(limit: u64) -> Self {
        Self::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "body_too_large",
            "Request body too large",
            format!("the request body exceeds the limit of {limit} bytes"),
        )
        .with_limit(limit)
    }
    /// The request's URI (path and query) is longer than [`super::MAX_URI_BYTES`].
    pub fn uri_too_long(length: usize, limit: usize) -> Self {
        Self::new(
            StatusCode::URI_TOO_LONG,
            "uri_too_long",
            "URI too long",
            format!("the request URI is {length} bytes, more than the limit of {limit} bytes"),
        )
        .with_limit(limit as u64)
    }
    pub fn unsupported_media_type(detail: impl Into<String>) -> Self {
        Self::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "unsupported_media_type",
            "Unsupported media type",
            detail,
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
    /// The answers being sent fill `--answers-in-flight-mb`: this one was built and dropped.
    pub fn answers_in_flight(budget_bytes: u64) -> Self {
        let mut e = Self::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "answers_in_flight",
            "Too many answers in flight",
            format!(
                "the answers being sent to clients hold the server's budget of {budget_bytes} \
                 bytes; retry shortly"
            ),
        )
        .with_limit(budget_bytes);
        e.retry_after_s = Some(1);
        e
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
        app::Error::from(error).into()
    }
}

/// The one mapping of the application's errors to problems: status, code, title, the field
/// and limit they name, and `Retry-After` where waiting helps. The detail is the error's text.
impl From<app::Error> for ApiError {
    fn from(error: app::Error) -> Self {
        use app::Error as E;
        let detail = error.to_string();
        match error {
            E::NotFound { field, .. } => {
                let mut e = Self::new(StatusCode::NOT_FOUND, "not_found", "Not found", detail);
                e.problem.field = field;
                e
            }
            E::Invalid { field, .. } => Self::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid_field",
                "Invalid field",
                detail,
            )
            .with_field(field),
            E::InvalidScenario(error) => Self::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid_scenario",
                "Invalid scenario",
                detail,
            )
            .with_field(error.field),
            E::LimitExceeded { field, limit, .. } => Self::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "limit_exceeded",
                "Limit exceeded",
                detail,
            )
            .with_field(field)
            .with_limit(limit),
            E::QueueFull { limit } => {
                let mut e = Self::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "queue_full",
                    "Job queue full",
                    detail,
                )
                .with_limit(limit as u64);
                e.retry_after_s = Some(5);
                e
            }
            E::Busy {
                limit,
                retry_after_s,
                ..
            } => {
                let mut e = Self::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "busy",
                    "Server busy",
                    detail,
                )
                .with_limit(limit as u64);
                e.retry_after_s = Some(retry_after_s);
                e
            }
            E::Unavailable { .. } => {
                let mut e = Self::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "store_unavailable",
                    "Shared store unavailable",
                    detail,
                );
                e.retry_after_s = Some(1);
                e
            }
            // No Retry-After: waiting does not make room in Redis.
            E::StoreFull { .. } => Self::new(
                StatusCode::INSUFFICIENT_STORAGE,
                "store_full",
                "Shared store full",
                detail,
            ),
            E::RegistryFull { retry, .. } => {
                let mut e = Self::new(
                    StatusCode::INSUFFICIENT_STORAGE,
                    "registry_full",
                    "Scenario registry full",
                    detail,
                );
                // Room comes back as live jobs end (the only scenarios never evicted).
                e.retry_after_s = retry.then_some(5);
                e
            }
            E::ScenarioProtected { .. } => Self::new(
                StatusCode::CONFLICT,
                "scenario_protected",
                "Scenario is part of the configuration",
                detail,
            ),
            E::ScenarioInUse { job_id, .. } => Self::new(
                StatusCode::CONFLICT,
                "scenario_in_use",
                "Scenario in use",
                detail,
            )
            .with_job(job_id),
            E::MapNotReady { job_id, .. } => Self::new(
                StatusCode::CONFLICT,
                "map_not_ready",
                "Map not ready",
                detail,
            )
            .with_job(job_id),
            E::PlacementNotReady { job_id } => Self::new(
                StatusCode::CONFLICT,
                "placement_not_ready",
                "Placement not ready",
                detail,
            )
            .with_job(job_id),
            E::CheckNotReady { job_id } => Self::new(
                StatusCode::CONFLICT,
                "check_not_ready",
                "Check not ready",
                detail,
            )
            .with_job(job_id),
            E::FleetPlanNotReady { job_id } => Self::new(
                StatusCode::CONFLICT,
                "fleet_plan_not_ready",
                "Fleet plan not ready",
                detail,
            )
            .with_job(job_id),
            E::JobFinished { .. } => Self::new(
                StatusCode::CONFLICT,
                "job_finished",
                "Job already finished",
                detail,
            ),
            E::BuildFailed(_) => Self::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "build_failed",
                "Map build failed",
                detail,
            ),
            E::Unauthorized(_) => Self::new(
                StatusCode::UNAUTHORIZED,
                "unauthorized",
                "Unauthorized",
                detail,
            ),
            E::Internal(_) => Self::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal_error",
                "Internal error",
                detail,
            ),
        }
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
/// A key repeated in an object is refused (422 naming the object's path and the key): serde
/// keeps the last value of a repeated key in a map or a `Value` (a scenario inside a body),
/// and refuses it only in a struct, so the check runs on the text whichever way it is read
/// ([`irs_answers::json::check_unique_keys`], the check scenario files get too).
///
/// A body that `T` reads straight from the text is taken as read: building the `Value` first
/// was a twentieth of a repeated path query's time, and a body the streaming parser accepts
/// reads the same through a `Value`. Only a body it refuses goes the slower way, for its error.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, ApiError> {
    let unique_keys = || {
        irs_answers::json::check_unique_keys(bytes)
            .map_err(|e| ApiError::from(app::Error::invalid(e.field, e.reason)))
    };
    if let Ok(parsed) = serde_json::from_slice(bytes) {
        unique_keys()?;
        return Ok(parsed);
    }
    let value: serde_json::Value =
        serde_json::from_slice(bytes).map_err(|e| ApiError::malformed_json(e.to_string()))?;
    unique_keys()?;
    irs_answers::json::from_value_at_path(value)
        .map_err(|e| ApiError::from(app::Error::invalid(e.field, e.reason)))
}
