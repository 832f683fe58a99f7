//! Monte Carlo check jobs: a path's check too long to run while a request waits (over
//! [`SYNC_CHECK_S`] of estimated CPU) runs as a job with progress (waypoints done) and cancel,
//! and the path answer with its report is kept in the job, as a placement's ranking is.

use super::Jobs;
use super::job::{Job, Work};
use crate::app::Error;
use crate::app::identity::Owner;
use crate::ids::ScenarioId;
use irs_model::radiomap::{Progress, WorkError};
use std::sync::{Arc, OnceLock};
use tracing::Instrument;

/// Checks estimated over this many seconds of CPU run as jobs (202); shorter ones are answered
/// while the request waits, within its timeout.
pub const SYNC_CHECK_S: f64 = 2.0;

/// A finished check: the path answer with its Monte Carlo report, as the API answers it.
pub struct CheckOutcome {
    /// The answer as JSON: what `GET /v1/checks/{id}` answers, and what a data directory keeps.
    pub answer: serde_json::Value,
    /// What the answer weighs in the job history (`--job-history-mb`): its JSON text's length.
    pub bytes: usize,
}

impl CheckOutcome {
    pub fn new(answer: serde_json::Value) -> Self {
        let bytes = serde_json::to_vec(&answer).map_or(0, |text| text.len());
        CheckOutcome { answer, bytes }
    }
}

impl Jobs {
    /// Starts a check of a path of `scenario_id`'s map as a job (503 when the queue is full).
    /// `check` runs on the blocking pool with the job's progress and returns the answer.
    pub fn check(
        self: &Arc<Self>,
        scenario_id: ScenarioId,
        owner: Option<Owner>,
        check: impl FnOnce(&Progress) -> Result<serde_json::Value, WorkError> + Send + 'static,
    ) -> Result<Arc<Job>, Error> {
        self.check_room()?;
        let job = self.admit(
            scenario_id,
            owner,
            Work::Check {
                outcome: OnceLock::new(),
            },
        );
        metrics::counter!("irs_checks_total").increment(1);
        let span = tracing::info_span!("job", job_id = %job.id, kind = "check", scenario_id = %job.scenario_id);
        let progress = job.progress.clone();
        let work = move || check(&progress);
        let finish = |job: Arc<Job>, answer: serde_json::Value| async move {
            if let Work::Check { outcome } = &job.work {
                let _ = outcome.set(Arc::new(CheckOutcome::new(answer)));
            }
        };
        crate::tasks::spawn(self.clone().run(job.clone(), work, finish).instrument(span));
        Ok(job)
    }
}
