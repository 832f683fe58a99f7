//! Who asked for each map (with tokens on): per map id, the owners who requested it. A map is
//! content-addressed, so two tenants asking for the same floor get the same map id; the claim
//! is what keeps them apart — a tenant without one is told the map does not exist, a `DELETE`
//! withdraws only the caller's claim, and the map itself goes with the last one.
//!
//! This is the store of one replica: in memory, or with `--data-dir` in `DIR/map-owners/<id>.rec`
//! (written atomically like every record there, read with the bounded reader, and removed with
//! the map's own file). A cluster keeps the claims in Redis instead (`irs:map-owners:<id>`), and
//! [`crate::app::App`] chooses which store to ask. Claims of a map that is evicted or deleted
//! are pruned with it ([`MapOwners::forget_unless_kept`] from the cache's eviction listener).

use crate::app::identity::{Owner, Owners};
use crate::ids::MapId;
use crate::store::{DataDir, Kind};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

/// A map's claims as the data directory keeps them. Persisted: a field added must default
/// when absent.
#[derive(Serialize, Deserialize)]
struct MapOwnersRecord {
    /// Owner digests (never tokens), sorted.
    owners: Vec<String>,
}

/// The claims on the maps of this replica.
pub(crate) struct MapOwners {
    /// Without a data directory: the claims, by map id.
    memory: Mutex<HashMap<MapId, Owners>>,
    /// With `--data-dir`: the claims live in its files (and not in `memory`), so they survive
    /// a restart with the maps they describe.
    disk: Option<Arc<DataDir>>,
    /// Serialises each read-modify-write of the claims, so two concurrent claims both land.
    changes: Mutex<()>,
}

impl MapOwners {
    pub fn new(disk: Option<Arc<DataDir>>) -> Self {
        MapOwners {
            memory: Mutex::new(HashMap::new()),
            disk,
            changes: Mutex::new(()),
        }
    }

    fn load(&self, map_id: &MapId) -> Owners {
        match &self.disk {
            Some(disk) => disk
                .load_one_json::<MapOwnersRecord>(Kind::MapOwners, map_id.as_str())
                .map(|r| Owners::from_digests(r.owners))
                .unwrap_or_default(),
            None => self
                .memory
                .lock()
                .expect("map owners lock")
                .get(map_id)
                .cloned()
                .unwrap_or_default(),
        }
    }

    fn save(&self, map_id: &MapId, owners: Owners) {
        match &self.disk {
            Some(disk) if owners.is_empty() => disk.remove_json(Kind::MapOwners, map_id.as_str()),
            Some(disk) => disk.save_json(
                Kind::MapOwners,
                map_id.as_str(),
                &MapOwnersRecord {
                    owners: owners.digests(),
                },
            ),
            None => {
                let mut memory = self.memory.lock().expect("map owners lock");
                if owners.is_empty() {
                    memory.remove(map_id);
                } else {
                    memory.insert(map_id.clone(), owners);
                }
            }
        }
    }

    /// Records that `owner` asked for the map (idempotent).
    pub fn claim(&self, map_id: &MapId, owner: &Owner) {
        let _serial = self.changes.lock().expect("map owners lock");
        let mut owners = self.load(map_id);
        if owners.insert(owner.clone()) {
            self.save(map_id, owners);
        }
    }

    /// Whether `owner` asked for the map.
    pub fn has(&self, map_id: &MapId, owner: &Owner) -> bool {
        self.load(map_id).contains(owner)
    }

    /// Withdraws `owner`'s claim: the owners left, or `None` if it had none.
    pub fn withdraw(&self, map_id: &MapId, owner: &Owner) -> Option<usize> {
        let _serial = self.changes.lock().expect("map owners lock");
        let mut owners = self.load(map_id);
        if !owners.remove(owner) {
            return None;
        }
        let left = owners.len();
        self.save(map_id, owners);
        Some(left)
    }

    /// Forgets every claim on a map that no longer exists (deleted, or a build that ended
    /// without one).
    pub fn forget(&self, map_id: &MapId) {
        let _serial = self.changes.lock().expect("map owners lock");
        self.save(map_id, Owners::default());
    }

    /// The cache let go of a map: its claims go too, unless the data directory still holds the
    /// map (then they go with its file).
    pub fn forget_unless_kept(&self, map_id: &MapId) {
        match &self.disk {
            Some(disk) if disk.has_map(map_id.as_str()) => {}
            _ => self.forget(map_id),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn claims_are_withdrawn_one_owner_at_a_time() {
        let claims = MapOwners::new(None);
        let (map, a, b) = (
            MapId::given("ab".repeat(16)),
            Owner::from_digest("aaaa".into()),
            Owner::from_digest("bbbb".into()),
        );
        assert!(!claims.has(&map, &a));
        claims.claim(&map, &a);
        claims.claim(&map, &b);
        claims.claim(&map, &a);
        assert!(claims.has(&map, &a) && claims.has(&map, &b));
        assert_eq!(claims.withdraw(&map, &a), Some(1));
        assert_eq!(claims.withdraw(&map, &a), None, "a claim is withdrawn once");
        assert!(!claims.has(&map, &a) && claims.has(&map, &b));
        assert_eq!(claims.withdraw(&map, &b), Some(0));
        assert!(
            claims.memory.lock().unwrap().is_empty(),
            "nothing kept for a map nobody wants"
        );
    }
}
