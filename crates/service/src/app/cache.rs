//! The map cache: built maps by map id in memory (moka, bounded by bytes through a weigher),
//! backed by the data directory with `--data-dir`, and each queried map's widest-path index.

use super::registry::ScenarioRegistry;
use crate::ids::{MapId, ScenarioId};
use crate::store::DataDir;
use crate::store::Store;
use irs_model::input::FieldError;
use irs_model::planner::UnitIndex;
use irs_model::radiomap::{RadioMap, Unit};
use std::sync::Arc;

/// Built maps by map id, weighed in KiB so the budget is in bytes, not entries; with
/// `--data-dir`, backed by the maps on disk (a memory miss reads the disk, a new map is written
/// to both, a deleted one leaves both).
#[derive(Clone)]
pub struct MapCache {
    maps: moka::future::Cache<MapId, Arc<RadioMap>>,
    /// Each queried map's values and widest-path index per unit queried ([`UnitIndex`]: 8 bytes
    /// a cell, 16 for a unit other than the map's own), built by its first path or sweep query
    /// in that unit. Its own budget, a quarter of the maps', holds the indexes of the maps being
    /// queried; an evicted one is rebuilt on demand (≈ 0.1 s for 1001² cells). Map ids hash the
    /// map's inputs, so an index can never outlive the map it describes.
    indexes: moka::sync::Cache<(MapId, Unit), Arc<UnitIndex>>,
    disk: Option<MapDisk>,
}

/// The disk behind the cache, and the registry that decodes its maps (a stored map is read
/// against its scenario).
#[derive(Clone)]
pub struct MapDisk {
    pub dir: Arc<DataDir>,
    pub scenarios: Arc<ScenarioRegistry>,
}

impl MapCache {
    /// `store` keeps the claims on the maps: a map the cache lets go of (evicted, removed)
    /// and the data directory does not keep takes its claims with it.
    pub fn new(budget_bytes: u64, disk: Option<MapDisk>, store: Arc<dyn Store>) -> Self {
        // Least recently used, not moka's default TinyLFU: TinyLFU may refuse a new entry it
        // has seen once, and a map is requested once before it is built, so a map that was
        // just built (minutes of CPU) could be dropped at once while old ones stay.
        let maps = moka::future::Cache::builder()
            .eviction_policy(moka::policy::EvictionPolicy::lru())
            .max_capacity((budget_bytes / 1024).max(1))
            .weigher(|_id: &MapId, map: &Arc<RadioMap>| {
                (map.size_bytes() / 1024).clamp(1, u32::MAX as usize) as u32
            })
            .eviction_listener(move |id: Arc<MapId>, _, cause| {
                if cause != moka::notification::RemovalCause::Replaced {
                    store.forget_claims(&id);
                }
            })
            .build();
        let indexes = moka::sync::Cache::builder()
            .eviction_policy(moka::policy::EvictionPolicy::lru())
            .max_capacity((budget_bytes / 4 / 1024).max(1))
            .weigher(|_key: &(MapId, Unit), index: &Arc<UnitIndex>| {
                (index.bytes() / 1024).clamp(1, u32::MAX as usize) as u32
            })
            .build();
        MapCache {
            maps,
            indexes,
            disk,
        }
    }

    /// Looks a map up in memory, then on disk, counting hits (memory or disk) and misses.
    pub async fn get(&self, map_id: &MapId) -> Option<Arc<RadioMap>> {
        if let Some(map) = self.maps.get(map_id).await {
            metrics::counter!("irs_map_cache_requests_total", "outcome" => "hit").increment(1);
            return Some(map);
        }
        let loaded = match &self.disk {
            Some(disk) if disk.dir.has_map(map_id.as_str()) => {
                let disk = disk.clone();
                let id = map_id.clone();
                // Reading and checking a map of megabytes is blocking work.
                crate::tasks::spawn_blocking(move || {
                    disk.dir.load_map(id.as_str(), |sid| {
                        disk.scenarios
                            .get(&ScenarioId::given(sid))
                            .map(|s| s.scenario.clone())
                    })
                })
                .await
                .ok()
                .flatten()
            }
            _ => None,
        };
        let outcome = if loaded.is_some() { "disk" } else { "miss" };
        metrics::counter!("irs_map_cache_requests_total", "outcome" => outcome).increment(1);
        let map = Arc::new(loaded?);
        self.maps.insert(map_id.clone(), map.clone()).await;
        self.record_size();
        Some(map)
    }

    /// Caches a new map, and writes it to the data directory (before returning: a finished
    /// job's map is on disk by the time the job says `done`).
    pub async fn insert(&self, map_id: MapId, map: Arc<RadioMap>) {
        if let Some(disk) = &self.disk {
            let (dir, id, to_save) = (disk.dir.clone(), map_id.clone(), map.clone());
            let _ = crate::tasks::spawn_blocking(move || dir.save_map(id.as_str(), &to_save)).await;
        }
        self.maps.insert(map_id, map).await;
        self.maps.run_pending_tasks().await;
        self.record_size();
    }

    /// The values in `unit` and widest-path index of a cached map, built on first use by the
    /// calling thread (a query worker; concurrent first queries wait for one build); an error
    /// names `unit` when the map cannot be read in it.
    pub fn unit_index(
        &self,
        map_id: &MapId,
        map: &RadioMap,
        unit: Unit,
    ) -> Result<Arc<UnitIndex>, FieldError> {
        self.indexes
            .try_get_with((map_id.clone(), unit), || {
                UnitIndex::new(map, unit).map(Arc::new)
            })
            .map_err(|e| (*e).clone())
    }

    /// Fills memory from the disk, most recently written first, up to `budget_bytes`: a
    /// restarted server answers its listing and its first queries from memory.
    pub async fn warm(&self, budget_bytes: u64) {
        let Some(disk) = &self.disk else { return };
        let mut loaded = 0usize;
        let mut held = 0u64;
        for map_id in disk.dir.map_ids() {
            let Some(map) = self.get(&MapId::given(map_id)).await else {
                continue;
            };
            held += map.size_bytes() as u64;
            loaded += 1;
            if held >= budget_bytes {
                break;
            }
        }
        tracing::info!(
            maps = loaded,
            bytes = held,
            "maps loaded from the data directory"
        );
    }

    pub fn record_size(&self) {
        metrics::gauge!("irs_map_cache_entries").set(self.maps.entry_count() as f64);
        metrics::gauge!("irs_map_cache_bytes").set((self.maps.weighted_size() * 1024) as f64);
    }

    /// The cached maps (id and map), for listing.
    pub fn entries(&self) -> Vec<(MapId, Arc<RadioMap>)> {
        self.maps.iter().map(|(k, v)| ((*k).clone(), v)).collect()
    }

    /// Drops a map's indexes, in every unit.
    fn forget_indexes(&self, map_id: &MapId) {
        for unit in Unit::ALL {
            self.indexes.invalidate(&(map_id.clone(), unit));
        }
    }

    /// Drops a map from memory and disk; true if it was held.
    pub async fn remove(&self, map_id: &MapId) -> bool {
        let mut removed = self.maps.remove(map_id).await.is_some();
        self.forget_indexes(map_id);
        if let Some(disk) = &self.disk {
            removed |= disk.dir.remove_map(map_id.as_str());
        }
        self.record_size();
        removed
    }

    /// Drops every map of a deleted scenario, from memory and disk.
    pub async fn remove_scenario_maps(&self, scenario_id: &ScenarioId) {
        for (map_id, map) in self.entries() {
            if map.key.scenario_id == scenario_id.as_str() {
                self.maps.remove(&map_id).await;
                self.forget_indexes(&map_id);
            }
        }
        if let Some(disk) = &self.disk {
            disk.dir.remove_maps_of(scenario_id.as_str());
        }
        self.record_size();
    }
}
