//! The store of a lone node with `--data-dir`: the claims on its maps in
//! `DIR/map-owners/<map id>.rec`, written atomically like every record there, read with the
//! bounded reader and removed with the map's own file, so they survive a restart with the maps
//! they describe. Nothing else is shared, because no other node exists to share it with.

use super::disk::{DataDir, Kind};
use super::{Error, Store};
use crate::ids::MapId;
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;

/// A map's claims as the data directory keeps them. Persisted: a field added must default
/// when absent.
#[derive(Serialize, Deserialize)]
struct MapOwnersRecord {
    /// Owner digests (never tokens), sorted.
    owners: Vec<String>,
}

impl DataDir {
    fn claims(&self, map_id: &MapId) -> BTreeSet<String> {
        self.load_one_json::<MapOwnersRecord>(Kind::MapOwners, map_id.as_str())
            .map(|r| r.owners.into_iter().collect())
            .unwrap_or_default()
    }

    fn save_claims(&self, map_id: &MapId, owners: BTreeSet<String>) {
        if owners.is_empty() {
            self.remove_json(Kind::MapOwners, map_id.as_str());
        } else {
            let owners = owners.into_iter().collect();
            self.save_json(
                Kind::MapOwners,
                map_id.as_str(),
                &MapOwnersRecord { owners },
            );
        }
    }

    /// Runs a read-modify-write of a map's claims alone, so two concurrent claims both land.
    fn change_claims<T>(
        &self,
        map_id: &MapId,
        change: impl FnOnce(&mut BTreeSet<String>) -> T,
    ) -> T {
        let _serial = self.claims_serial.lock().expect("claims lock");
        let before = self.claims(map_id);
        let mut owners = before.clone();
        let out = change(&mut owners);
        if owners != before {
            self.save_claims(map_id, owners);
        }
        out
    }
}

// The claims are small files: read and written on the calling thread, as the claims in memory
// are (a blocking write here costs what the request's own disk writes do).
#[async_trait::async_trait]
impl Store for DataDir {
    async fn claim_map(&self, map_id: &MapId, owner: &str) -> Result<(), Error> {
        self.change_claims(map_id, |owners| owners.insert(owner.to_string()));
        Ok(())
    }

    async fn map_claimed(&self, map_id: &MapId, owner: &str) -> Result<bool, Error> {
        Ok(self.claims(map_id).contains(owner))
    }

    async fn withdraw_map(&self, map_id: &MapId, owner: &str) -> Result<Option<usize>, Error> {
        Ok(self.change_claims(map_id, |owners| {
            owners.remove(owner).then_some(owners.len())
        }))
    }

    /// The claims go with the map's file: while the directory keeps the map, they stay.
    fn forget_claims(&self, map_id: &MapId) {
        if !self.has_map(map_id.as_str()) {
            self.change_claims(map_id, |owners| owners.clear());
        }
    }
}
