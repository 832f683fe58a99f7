//! One truth across replicas: what one replica deletes, every other forgets. A replica that
//! deletes a scenario or a map removes it from the shared store (a scenario with every map
//! built from it) and announces it on a Redis channel; this loop, on every replica, drops its
//! own copies (registry, map cache, data directory) as the announcements arrive, within a
//! round trip of the delete.
//!
//! Redis's pub/sub is at most once: a replica cut off from Redis when a delete happens misses
//! it and keeps its copy until its cache lets go of it; the shared store no longer has it, so
//! no other replica gets it back from there.

use super::App;
use crate::ids::ScenarioId;
use crate::store::Store as _;
use crate::store::redis::{Cluster, Deleted, HEALTH_PERIOD};
use futures_util::StreamExt;
use std::sync::Arc;

/// Follows the deletions announced in the cluster, subscribing again whenever the connection
/// drops.
pub(crate) async fn follow(state: App, cluster: Arc<Cluster>) {
    loop {
        if cluster.unavailable().is_none() {
            match cluster.deletions().await {
                Ok(announced) => {
                    tracing::debug!("following the cluster's deletions");
                    let mut announced = std::pin::pin!(announced);
                    while let Some(deleted) = announced.next().await {
                        state.forget_deleted(deleted).await;
                    }
                }
                Err(e) => tracing::debug!(error = %e, "cannot follow the cluster's deletions yet"),
            }
        }
        tokio::time::sleep(HEALTH_PERIOD).await;
    }
}

impl App {
    /// Drops this replica's copies of what another replica (or this one) deleted.
    pub(crate) async fn forget_deleted(&self, deleted: Deleted) {
        match deleted {
            Deleted::Scenario(id) => self.forget_scenario(&id).await,
            Deleted::Map(id) => {
                if self.cache().remove(&id).await {
                    tracing::info!(map_id = %id, "map deleted on another replica: dropped here");
                }
            }
        }
    }

    async fn forget_scenario(&self, id: &ScenarioId) {
        if self.registry().forget(id) {
            tracing::info!(scenario_id = %id, "scenario deleted on another replica: dropped here");
        }
        self.cache().remove_scenario_maps(id).await;
    }
}
