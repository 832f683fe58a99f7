//! Jobs as the API sees them, wherever they run: a job of this replica, or (in a cluster) one
//! another replica runs, seen through its record in the shared store and cancelled through it.

use super::identity::Caller;
use super::{App, Error};
use crate::app::jobs::{JobRecord, JobView};
use crate::ids::JobId;

impl App {
    /// A job by id: this replica's, else another replica's as its builder last recorded it.
    pub(crate) async fn job(&self, id: &JobId) -> Result<JobView, Error> {
        if let Some(job) = self.jobs().get(id) {
            return Ok(job.view());
        }
        if let Some(cluster) = self.cluster()
            && let Some(record) = cluster.job::<JobRecord>(id).await?
        {
            return Ok(record.view);
        }
        Err(Error::not_found("job", id))
    }

    /// Cancels a queued or running job of `caller`'s (a job of another token is not found);
    /// returns it as it was when asked.
    pub(crate) async fn cancel_job(&self, id: &JobId, caller: &Caller) -> Result<JobView, Error> {
        let local = self.jobs().get(id).is_some();
        if let Some(cluster) = self.cluster().filter(|_| !local) {
            // Another replica runs it: it reads the request at its next heartbeat.
            let record = cluster
                .job::<JobRecord>(id)
                .await?
                .filter(|r| caller.may_touch(r.owner().as_ref()))
                .ok_or_else(|| Error::not_found("job", id))?;
            if record.view.state.is_terminal() {
                return Err(Error::JobFinished {
                    job_id: id.clone(),
                    state: record.view.state,
                });
            }
            cluster.request_cancel(id).await?;
            return Ok(record.view);
        }
        let job = self.jobs().cancel(id, caller)?;
        if let Some(cluster) = self.cluster() {
            // Also through the store, for a build whose local job is only a mirror; the local
            // cancellation has happened either way, so a store that is down changes nothing.
            let _ = cluster.request_cancel(id).await;
        }
        Ok(job.view())
    }

    /// Whether the shared store can be used now (always, without one): `/readyz` reports a
    /// replica whose store is down as not ready.
    pub(crate) fn store_available(&self) -> Result<(), Error> {
        match self.cluster().and_then(|c| c.unavailable()) {
            Some(reason) => Err(Error::unavailable(reason)),
            None => Ok(()),
        }
    }
}
