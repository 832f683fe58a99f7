//! The store of a lone node without a data directory: the claims on its maps, in memory.
//! Nothing else is shared, because no other node exists to share it with.

use super::{Error, Store};
use crate::ids::MapId;
use std::collections::{BTreeSet, HashMap};
use std::sync::Mutex;

/// Owner digests by map id.
#[derive(Default)]
pub(crate) struct Memory {
    claims: Mutex<HashMap<MapId, BTreeSet<String>>>,
}

impl Memory {
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.claims.lock().expect("claims lock").is_empty()
    }
}

#[async_trait::async_trait]
impl Store for Memory {
    async fn claim_map(&self, map_id: &MapId, owner: &str) -> Result<(), Error> {
        let mut claims = self.claims.lock().expect("claims lock");
        claims
            .entry(map_id.clone())
            .or_default()
            .insert(owner.to_string());
        Ok(())
    }

    async fn map_claimed(&self, map_id: &MapId, owner: &str) -> Result<bool, Error> {
        let claims = self.claims.lock().expect("claims lock");
        Ok(claims.get(map_id).is_some_and(|o| o.contains(owner)))
    }

    async fn withdraw_map(&self, map_id: &MapId, owner: &str) -> Result<Option<usize>, Error> {
        let mut claims = self.claims.lock().expect("claims lock");
        let Some(owners) = claims.get_mut(map_id) else {
            return Ok(None);
        };
        if !owners.remove(owner) {
            return Ok(None);
        }
        let left = owners.len();
        if left == 0 {
            claims.remove(map_id);
        }
        Ok(Some(left))
    }

    fn forget_claims(&self, map_id: &MapId) {
        self.claims.lock().expect("claims lock").remove(map_id);
    }
}
