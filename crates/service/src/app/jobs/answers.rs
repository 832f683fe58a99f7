//! Jobs whose result is one JSON answer: a path's Monte Carlo check too long to run while a
//! request waits (over [`SYNC_CHECK_S`] of estimated CPU), and a fleet plan too large to (over
//! the `sync_cells` the service answers at once). Each runs with progress and cancel, and its
//! answer is kept in the job, as a placement's ranking is.

use super::Jobs;
use super::job::{Job, JobKind, Work};
use crate::app::Error;
use crate::app::identity::Owner;
use crate::ids::{JobId, ScenarioId};
use irs_model::radiomap::{Progress, WorkError};
use std::sync::{Arc, OnceLock};
use tracing::Instrument;

/// Checks estimated over this many seconds of CPU run as jobs (202); shorter ones are answered
/// while the request waits, within its timeout.
pub const SYNC_CHECK_S: f64 = 2.0;

/// What a job with one JSON answer computes; its [`JobKind`] and where its answer is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnswerKind {
    /// A path answer with its Monte Carlo report (`GET /v1/checks/{id}`).
    Check,
    /// A fleet plan (`GET /v1/fleet-plans/{id}`).
    Fleet,
}

impl AnswerKind {
    pub fn job_kind(self) -> JobKind {
        match self {
            AnswerKind::Check => JobKind::Check,
            AnswerKind::Fleet => JobKind::Fleet,
        }
    }

    /// Where the answer of job `id` is read.
    pub fn href(self, id: &JobId) -> String {
        match self {
            AnswerKind::Check => format!("/v1/checks/{id}"),
            AnswerKind::Fleet => format!("/v1/fleet-plans/{id}"),
        }
    }
}

/// A finished job's answer, as the API answers it.
pub struct AnswerOutcome {
    /// The answer as JSON: what its `result_href` answers, and what a data directory keeps.
    pub answer: serde_json::Value,
    /// What the answer weighs in the job history (`--job-history-mb`): its JSON text's length.
    pub bytes: usize,
}

impl AnswerOutcome {
    pub fn new(answer: serde_json::Value) -> Self {
        let bytes = serde_json::to_vec(&answer).map_or(0, |text| text.len());
        AnswerOutcome { answer, bytes }
    }
}

impl Jobs {
    /// Starts a job of `kind` on `scenario_id` (503 when the queue is full). `work` runs on the
    /// blocking pool with the job's progress and returns the answer.
    pub fn answer(
        self: &Arc<Self>,
        kind: AnswerKind,
        scenario_id: ScenarioId,
        owner: Option<Owner>,
        work: impl FnOnce(&Progress) -> Result<serde_json::Value, WorkError> + Send + 'static,
    ) -> Result<Arc<Job>, Error> {
        self.check_room()?;
        let job = self.admit(
            scenario_id,
            owner,
            Work::Answer {
                kind,
                outcome: OnceLock::new(),
            },
        );
        let name = kind.job_kind().as_str();
        match kind {
            AnswerKind::Check => metrics::counter!("irs_checks_total").increment(1),
            AnswerKind::Fleet => metrics::counter!("irs_fleet_plans_total").increment(1),
        }
        let span = tracing::info_span!("job", job_id = %job.id, kind = name, scenario_id = %job.scenario_id);
        let progress = job.progress.clone();
        let run = move || work(&progress);
        let finish = |job: Arc<Job>, answer: serde_json::Value| async move {
            if let Work::Answer { outcome, .. } = &job.work {
                let _ = outcome.set(Arc::new(AnswerOutcome::new(answer)));
            }
        };
        crate::tasks::spawn(self.clone().run(job.clone(), run, finish).instrument(span));
        Ok(job)
    }
}
