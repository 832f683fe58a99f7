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
use crate::store::redis::{Cluster, Deleted, HEALTH_PERIOD};
use futures_util::StreamExt;
use std::sync::Arc;
use std::time::Duration;

/// How long subscribing may take before it is tried again.
const SUBSCRIBE_TIMEOUT: Duration = Duration::from_secs(2);

/// Follows the deletions announced in the cluster, subscribing again whenever the subscription
/// ends or Redis was away since it was made (the health loop saw it go: the subscription's
/// connection may be dead without the stream noticing).
pub(crate) async fn follow(state: App, cluster: Arc<Cluster>) {
    loop {
        let since = cluster.up_since();
        if since.is_some() {
            match tokio::time::timeout(SUBSCRIBE_TIMEOUT, cluster.deletions()).await {
                Ok(Ok(announced)) => {
                    tracing::debug!("following the cluster's deletions");
                    let mut announced = std::pin::pin!(announced);
                    loop {
                        tokio::select! {
                            next = announced.next() => match next {
                                Some(deleted) => state.forget_deleted(deleted).await,
                                None => break,
                            },
                            _ = tokio::time::sleep(HEALTH_PERIOD) => {
                                if cluster.up_since() != since {
                                    break;
                                }
                            }
                        }
                    }
                    cluster.stopped_following();
                }
                Ok(Err(e)) => {
                    tracing::debug!(error = %e, "cannot follow the cluster's deletions yet")
                }
                Err(_) => tracing::debug!("subscribing to the cluster's deletions timed out"),
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
