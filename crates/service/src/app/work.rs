//! Jobs as the API sees them, wherever they run: a job of this replica, or (in a cluster) one
//! another replica runs, seen through its record in the shared store and cancelled through it.
//! A job belongs to every tenant that asked for its work (a shared build); only they see it,
//! and a cancel withdraws one of them.

use super::identity::Caller;
use super::{App, Error};

use crate::app::jobs::{Job, JobRecord, JobView};
use crate::ids::JobId;
use crate::store::Entry;

impl App {
    /// May `caller` see the job `id`? Its owners decide: a local job's own, or in a cluster a
    /// map build's `irs:job-owners` set (owners may join on any replica). A tenant that is
    /// not an owner is told the job does not exist.
    async fn owns_job(
        &self,
        caller: &Caller,
        id: &JobId,
        local: Option<&Job>,
    ) -> Result<bool, Error> {
        let shared = self
            .build_stream()
            .filter(|_| local.is_none_or(|j| j.map_id().is_some()));
        match (caller, shared, local) {
            (Caller::Owner(me), Some(cluster), _) => {
                Ok(cluster.job_owned_by(id, &me.to_string()).await?)
            }
            (_, _, Some(job)) => Ok(job.visible_to(caller)),
            (Caller::Open, _, None) => Ok(true),
            (_, _, None) => Ok(false),
        }
    }

    /// A job by id, for `caller`: this replica's, else another replica's as its builder last
    /// recorded it.
    pub(crate) async fn job(&self, caller: &Caller, id: &JobId) -> Result<JobView, Error> {
        let local = self.jobs().get(id);
        if !self.owns_job(caller, id, local.as_deref()).await? {
            return Err(Error::not_found("job", id));
        }
        if let Some(job) = local {
            return Ok(job.view());
        }
        if let Some(record) = self.store().record::<JobRecord>(Entry::Job(id)).await? {
            return Ok(record.view);
        }
        Err(Error::not_found("job", id))
    }

    /// Withdraws `caller`'s interest in a queued or running job (a job it does not own is not
    /// found); the job stops when no owner wants it any more (at once with authentication
    /// off), and a map job's claim on its map goes with the interest. Returns the job as it
    /// was when asked.
    pub(crate) async fn cancel_job(&self, id: &JobId, caller: &Caller) -> Result<JobView, Error> {
        let local = self.jobs().get(id);
        if !self.owns_job(caller, id, local.as_deref()).await? {
            return Err(Error::not_found("job", id));
        }
        let shared = self
            .build_stream()
            .filter(|_| local.as_ref().is_none_or(|j| j.map_id().is_some()));
        let Some(cluster) = shared else {
            let (job, _) = self.jobs().cancel(id, caller)?;
            self.withdraw_build_claim(caller, job.map_id()).await;
            return Ok(job.view());
        };
        // A cluster's map build: its record says where it is, its owners are in the store.
        let view = match self.store().record::<JobRecord>(Entry::Job(id)).await? {
            Some(record) => record.view,
            None => match &local {
                Some(job) => job.view(),
                None => return Err(Error::not_found("job", id)),
            },
        };
        if view.state.is_terminal() {
            return Err(Error::JobFinished {
                job_id: id.clone(),
                state: view.state,
            });
        }
        let stopping = match caller.owner() {
            // The store asks the builder to stop, in the same script, when this was the last.
            Some(me) => {
                cluster
                    .withdraw_job(id, &me.to_string())
                    .await?
                    .ok_or_else(|| Error::not_found("job", id))?
                    == 0
            }
            None => {
                cluster.request_cancel(id).await?;
                true
            }
        };
        if stopping && let Some(job) = &local {
            // This replica builds it: stop now rather than at the next heartbeat.
            self.jobs().cancel_local(job);
        }
        let map_id = view.key.as_ref().map(crate::ids::MapId::of);
        self.withdraw_build_claim(caller, map_id.as_ref()).await;
        Ok(view)
    }

    /// A cancelled map build's claim on its map goes with the caller's interest (the map, if
    /// the others' build finishes, is theirs).
    async fn withdraw_build_claim(&self, caller: &Caller, map_id: Option<&crate::ids::MapId>) {
        let (Some(me), Some(map_id)) = (caller.owner(), map_id) else {
            return;
        };
        if let Err(e) = self.store().withdraw_map(map_id, &me.to_string()).await {
            tracing::warn!(map_id = %map_id, error = %e, "a cancelled build's claim not withdrawn");
        }
    }

    /// What this node works without for now, and why. A degraded node still serves what it
    /// can (maps it holds, path queries on them) and refuses only what needs the missing part
    /// (503 naming it), so a load balancer keeps routing to it: when Redis is away from every
    /// replica, taking them all out of rotation would refuse even the answers they can give.
    pub(crate) fn degradations(&self) -> Vec<Degradation> {
        let store = self.store().unavailable().map(|reason| Degradation {
            component: Component::SharedStore,
            reason,
        });
        let disk = self
            .data_dir()
            .and_then(|dir| dir.unwritable())
            .map(|reason| Degradation {
                component: Component::DataDir,
                reason,
            });
        store.into_iter().chain(disk).collect()
    }
}

/// A part of the deployment a node works without for now.
pub(crate) struct Degradation {
    pub component: Component,
    pub reason: String,
}

/// The parts a node can lose and keep serving.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum Component {
    /// The store shared with the other replicas (`--redis-url`) cannot be reached: requests
    /// that need it answer 503 `store_unavailable`.
    SharedStore,
    /// The data directory (`--data-dir`) cannot be written (read-only, full): the node serves
    /// from memory and what it can read, and what it builds is not kept across a restart.
    DataDir,
}
