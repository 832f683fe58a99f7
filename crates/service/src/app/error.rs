//! The application's own error: what went wrong in terms of scenarios, maps, jobs, queries and
//! callers, with no status code and no wire format. Its text (`Display`) is the `detail` a
//! client reads; `http::problem` alone maps each variant to its status, problem code, title and
//! headers (problem+json), so the caches, jobs, the query pool, identity and the cluster never
//! build an HTTP answer.

use crate::app::jobs::JobState;
use crate::app::registry::ScenarioSource;
use crate::ids::{JobId, MapId, ScenarioId};
use irs_model::input::FieldError;

/// Why the application refused or failed a request.
#[derive(Debug, Clone, thiserror::Error)]
pub(crate) enum Error {
    /// No such scenario, map, job or placement (`what`); `field` names the request field that
    /// gave the id, when one did.
    #[error("no {what} with id {id:?}")]
    NotFound {
        what: &'static str,
        id: String,
        field: Option<String>,
    },
    /// A request field with a value the application does not take.
    #[error("{reason}")]
    Invalid { field: String, reason: String },
    /// A scenario document that failed validation (its own code, so clients can tell a bad
    /// floor from a bad request parameter).
    #[error("{0}")]
    InvalidScenario(FieldError),
    /// A request past one of the server's limits (`limit` in the field's unit).
    #[error("{detail}")]
    LimitExceeded {
        field: String,
        limit: u64,
        detail: String,
    },
    /// `limit` map builds already wait for a worker (here, or in the whole cluster).
    #[error("{limit} map builds are already waiting for a worker; retry later")]
    QueueFull { limit: usize },
    /// Every query worker is taken and `limit` more heavy queries wait.
    #[error(
        "every query worker is busy and {limit} heavy queries already wait; this {what} was not started: retry later"
    )]
    Busy {
        what: &'static str,
        limit: usize,
        retry_after_s: u64,
    },
    /// The shared store (Redis, `--redis-url`) cannot be used now; the replica retries by
    /// itself.
    #[error(
        "{reason}; maps this replica holds still answer, everything else needs the shared store: retry shortly"
    )]
    Unavailable { reason: String },
    /// The shared store is full (Redis at its `maxmemory`): an operator must make room, so
    /// retrying does not help.
    #[error(
        "{reason}; the shared store has no room: its operator must raise Redis's maxmemory or lower --redis-maps-mb"
    )]
    StoreFull { reason: String },
    /// The scenario registry cannot take this scenario. `retry`: room comes back by itself
    /// (live jobs end), so the client is told when to try again; false for a scenario larger
    /// than the whole registry, which no wait admits.
    #[error("{detail}")]
    RegistryFull { detail: String, retry: bool },
    /// A built-in or file scenario: part of the configuration, never deleted.
    #[error("scenario {id} comes from the server's {origin} scenarios and cannot be deleted")]
    ScenarioProtected {
        id: ScenarioId,
        origin: ScenarioSource,
    },
    /// A live job needs the scenario.
    #[error("job {job_id} is building a map of scenario {id}; cancel it or wait")]
    ScenarioInUse { id: ScenarioId, job_id: JobId },
    /// The map is being built.
    #[error("map {map_id} is being built by job {job_id}; poll /v1/jobs/{job_id}")]
    MapNotReady { map_id: MapId, job_id: JobId },
    /// The placement search is still running.
    #[error("placement {job_id} is still running; poll /v1/jobs/{job_id}")]
    PlacementNotReady { job_id: JobId },
    /// The Monte Carlo check is still running.
    #[error("check {job_id} is still running; poll /v1/jobs/{job_id}")]
    CheckNotReady { job_id: JobId },
    /// The fleet plan is still running.
    #[error("fleet plan {job_id} is still running; poll /v1/jobs/{job_id}")]
    FleetPlanNotReady { job_id: JobId },
    /// The job ended already (`state`: done, failed or cancelled).
    #[error("job {job_id} is already {state}")]
    JobFinished { job_id: JobId, state: JobState },
    /// A build or a search the request waited for ended without its result.
    #[error("{0}")]
    BuildFailed(String),
    /// The caller presented no token, or one the server does not accept.
    #[error("{0}")]
    Unauthorized(String),
    /// A fault of the server's, not of the request.
    #[error("{0}")]
    Internal(String),
}

impl Error {
    pub fn not_found(what: &'static str, id: impl ToString) -> Self {
        Error::NotFound {
            what,
            id: id.to_string(),
            field: None,
        }
    }
    /// The same error naming the request field it concerns.
    pub fn with_field(mut self, name: impl Into<String>) -> Self {
        if let Error::NotFound { field, .. } = &mut self {
            *field = Some(name.into());
        }
        self
    }
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Error::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
    pub fn limit_exceeded(field: impl Into<String>, limit: u64, detail: impl Into<String>) -> Self {
        Error::LimitExceeded {
            field: field.into(),
            limit,
            detail: detail.into(),
        }
    }
    pub fn unavailable(reason: impl Into<String>) -> Self {
        Error::Unavailable {
            reason: reason.into(),
        }
    }
    pub fn internal(detail: impl Into<String>) -> Self {
        Error::Internal(detail.into())
    }
}

/// A request field the engine rejected: `invalid_field` naming it.
impl From<FieldError> for Error {
    fn from(error: FieldError) -> Self {
        Error::Invalid {
            field: error.field,
            reason: error.reason,
        }
    }
}

/// The shared store's refusals, as the application reports them.
impl From<crate::store::Error> for Error {
    fn from(error: crate::store::Error) -> Self {
        match error {
            crate::store::Error::Unavailable { reason } => Error::Unavailable { reason },
            crate::store::Error::Full { limit } => Error::QueueFull { limit },
            crate::store::Error::NoRoom { reason } => Error::StoreFull { reason },
        }
    }
}
