//! What the service keeps in memory: the scenario registry (bounded by count and by bytes,
//! least recently used API scenarios evicted first) and the map cache (moka, bounded by bytes
//! through a weigher, keyed by the map id = hash of the map key).

use crate::app::Error;
use crate::app::identity::{Caller, Owner};
use crate::ids::{MapId, ScenarioId};
use crate::store::{DataDir, Kind};
use irs_answers::scenario::ScenarioDocument as _;
use irs_model::planner::{self, Bottlenecks};
use irs_model::radiomap::RadioMap;
use irs_model::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};

/// Where a registered scenario came from. Only API scenarios are evicted or deleted: the
/// others are the server's configuration.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ScenarioSource {
    /// Built into the binary.
    Builtin,
    /// A file of the scenarios directory, read at start-up.
    File,
    /// Sent to the API (registered, inline in a request, or a placement's candidate).
    Api,
}

impl ScenarioSource {
    /// Its name in listings (`source`) and error details.
    pub fn as_str(self) -> &'static str {
        match self {
            ScenarioSource::Builtin => "builtin",
            ScenarioSource::File => "file",
            ScenarioSource::Api => "api",
        }
    }
}

impl std::fmt::Display for ScenarioSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for ScenarioSource {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

/// A registered scenario.
#[derive(Debug)]
pub struct StoredScenario {
    pub id: ScenarioId,
    pub scenario: Arc<Scenario>,
    pub source: ScenarioSource,
    /// Its weight in the registry's byte budget: its canonical document and decoded raster.
    bytes: usize,
    /// The tokens that registered it (empty when authentication is off): each may delete its
    /// own registration, and the scenario goes with the last one.
    owners: Mutex<HashSet<Owner>>,
    /// The registry's clock at the last registration or lookup (least recently used = lowest).
    last_used: AtomicU64,
}

#[derive(Debug, Clone, Serialize)]
pub struct ScenarioSummary {
    pub id: ScenarioId,
    pub name: Option<String>,
    pub source: ScenarioSource,
    pub href: String,
}

impl StoredScenario {
    /// What a data directory or the shared store keeps of it: the document and the owners.
    pub(crate) fn record(&self) -> ScenarioRecord {
        let mut owners: Vec<String> = self
            .owners
            .lock()
            .expect("owners lock")
            .iter()
            .map(|o| o.to_string())
            .collect();
        owners.sort();
        ScenarioRecord {
            document: serde_json::from_str(&self.scenario.canonical_json())
                .expect("a canonical document is JSON"),
            owners,
        }
    }

    pub fn summary(&self) -> ScenarioSummary {
        ScenarioSummary {
            id: self.id.clone(),
            name: self.scenario.name.clone(),
            source: self.source,
            href: self.id.href(),
        }
    }

    /// May `caller` see it in a listing? The server's own scenarios are everybody's.
    fn visible_to(&self, caller: &Caller) -> bool {
        self.source != ScenarioSource::Api
            || *caller == Caller::Open
            || caller
                .owner()
                .is_some_and(|o| self.owners.lock().expect("owners lock").contains(&o))
    }
}

/// Scenarios by content hash; registering the same document twice is idempotent.
///
/// Inline scenarios in map requests are registered too, so without eviction a stream of them
/// would fill the registry for good. When it is full (by count or by bytes), a new scenario
/// replaces the least recently used ones registered through the API that no cached map and no
/// live job needs; only when there are none is the registration refused (507).
pub struct ScenarioRegistry {
    limit: usize,
    budget_bytes: usize,
    by_id: RwLock<HashMap<ScenarioId, Arc<StoredScenario>>>,
    clock: AtomicU64,
    /// With `--data-dir`: API scenarios are written there (with their owners) and removed when
    /// they are deleted or evicted, so the directory mirrors the registry.
    disk: Option<Arc<DataDir>>,
    /// Serialises the writes of one scenario's record, so the last write holds the last owners.
    disk_writes: Mutex<()>,
}

/// A scenario as the data directory keeps it.
#[derive(Serialize, Deserialize)]
pub(crate) struct ScenarioRecord {
    /// The canonical document (its hash is the file's name).
    pub document: serde_json::Value,
    /// Owner digests (never tokens).
    pub owners: Vec<String>,
}

impl ScenarioRegistry {
    pub fn new(limit: usize, budget_bytes: usize, disk: Option<Arc<DataDir>>) -> Self {
        ScenarioRegistry {
            limit,
            budget_bytes,
            by_id: RwLock::new(HashMap::new()),
            clock: AtomicU64::new(0),
            disk,
            disk_writes: Mutex::new(()),
        }
    }

    /// Writes an API scenario's record (its document and current owners) to the data directory.
    fn persist(&self, stored: &StoredScenario) {
        let Some(disk) = &self.disk else { return };
        if stored.source != ScenarioSource::Api {
            return;
        }
        let _serial = self.disk_writes.lock().expect("registry disk lock");
        // Held through the write: a deletion or eviction (which removes the file under the
        // write lock) cannot interleave, so a removed scenario's file never comes back.
        let by_id = self.by_id.read().expect("registry lock");
        if !by_id.contains_key(&stored.id) {
            return;
        }
        let record = stored.record();
        disk.save_json(Kind::Scenario, stored.id.as_str(), &record);
    }

    /// Removes a scenario's record; called under the registry's write lock.
    fn unpersist(&self, id: &ScenarioId) {
        if let Some(disk) = &self.disk {
            disk.remove_json(Kind::Scenario, id.as_str());
        }
    }

    fn tick(&self) -> u64 {
        self.clock.fetch_add(1, Ordering::Relaxed)
    }

    /// Registers a validated scenario for `owner`; returns it and whether it was new. `in_use`
    /// lists the scenarios that cached maps or live jobs need; it is asked only when the
    /// registry is full.
    pub fn register(
        &self,
        scenario: Scenario,
        source: ScenarioSource,
        owner: Option<Owner>,
        in_use: impl FnOnce() -> HashSet<ScenarioId>,
    ) -> Result<(Arc<StoredScenario>, bool), Error> {
        // One canonical form for both the id and the weight (a floor plan's is megabytes).
        let canonical = scenario.canonical_json();
        let id = ScenarioId::of_canonical(&canonical);
        let bytes = canonical.len() + scenario.raster_bytes();
        let mut by_id = self.by_id.write().expect("registry lock");
        if let Some(existing) = by_id.get(&id) {
            existing.last_used.store(self.tick(), Ordering::Relaxed);
            let added = owner
                .is_some_and(|owner| existing.owners.lock().expect("owners lock").insert(owner));
            let existing = existing.clone();
            drop(by_id);
            if added {
                self.persist(&existing);
            }
            return Ok((existing, false));
        }
        if bytes > self.budget_bytes {
            return Err(Error::RegistryFull(format!(
                "the scenario takes about {bytes} bytes, more than the registry's whole budget of {} bytes",
                self.budget_bytes
            )));
        }
        let mut held: usize = by_id.values().map(|s| s.bytes).sum();
        if by_id.len() >= self.limit || held + bytes > self.budget_bytes {
            let needed = in_use();
            let mut victims: Vec<(u64, ScenarioId, usize)> = by_id
                .values()
                .filter(|s| s.source == ScenarioSource::Api && !needed.contains(&s.id))
                .map(|s| (s.last_used.load(Ordering::Relaxed), s.id.clone(), s.bytes))
                .collect();
            victims.sort_unstable();
            let mut victims = victims.into_iter();
            while by_id.len() >= self.limit || held + bytes > self.budget_bytes {
                let Some((_, victim, freed)) = victims.next() else {
                    metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
                    return Err(Error::RegistryFull(format!(
                        "the registry holds {} scenarios in {held} bytes (limits: {} scenarios, \
                         {} bytes) and cached maps or live jobs need every one",
                        by_id.len(),
                        self.limit,
                        self.budget_bytes
                    )));
                };
                by_id.remove(&victim);
                self.unpersist(&victim);
                held -= freed;
                metrics::counter!("irs_scenarios_evicted_total").increment(1);
                tracing::info!(scenario_id = %victim, "least recently used scenario evicted");
            }
        }
        let stored = Arc::new(StoredScenario {
            id: id.clone(),
            scenario: Arc::new(scenario),
            source,
            bytes,
            owners: Mutex::new(owner.into_iter().collect()),
            last_used: AtomicU64::new(self.tick()),
        });
        by_id.insert(id, stored.clone());
        metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
        metrics::gauge!("irs_scenario_bytes").set((held + bytes) as f64);
        drop(by_id);
        self.persist(&stored);
        Ok((stored, true))
    }

    pub fn get(&self, id: &ScenarioId) -> Option<Arc<StoredScenario>> {
        let found = self.by_id.read().expect("registry lock").get(id).cloned();
        if let Some(s) = &found {
            s.last_used.store(self.tick(), Ordering::Relaxed);
        }
        found
    }

    /// Removes `caller`'s registration of an API scenario; the scenario goes with its last
    /// registration (true then). Built-in and preloaded files stay (409); a scenario the caller
    /// did not register is not found (404), as if it were not there.
    pub fn delete(&self, id: &ScenarioId, caller: &Caller) -> Result<bool, Error> {
        let mut by_id = self.by_id.write().expect("registry lock");
        let Some(stored) = by_id.get(id) else {
            return Err(Error::not_found("scenario", id));
        };
        if stored.source != ScenarioSource::Api {
            return Err(Error::ScenarioProtected {
                id: id.clone(),
                origin: stored.source,
            });
        }
        let gone = {
            let mut owners = stored.owners.lock().expect("owners lock");
            match caller {
                Caller::Open => true,
                Caller::Anonymous => return Err(Error::not_found("scenario", id)),
                Caller::Owner(me) => {
                    if !owners.remove(me) {
                        return Err(Error::not_found("scenario", id));
                    }
                    owners.is_empty()
                }
            }
        };
        if gone {
            by_id.remove(id);
            self.unpersist(id);
            metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
            let held: usize = by_id.values().map(|s| s.bytes).sum();
            metrics::gauge!("irs_scenario_bytes").set(held as f64);
        } else {
            let stored = stored.clone();
            drop(by_id);
            self.persist(&stored);
        }
        Ok(gone)
    }

    /// The scenarios `caller` may see, by id.
    pub fn list(&self, caller: &Caller) -> Vec<ScenarioSummary> {
        let mut all: Vec<ScenarioSummary> = self
            .by_id
            .read()
            .expect("registry lock")
            .values()
            .filter(|s| s.visible_to(caller))
            .map(|s| s.summary())
            .collect();
        all.sort_by(|a, b| a.id.cmp(&b.id));
        all
    }

    pub fn len(&self) -> usize {
        self.by_id.read().expect("registry lock").len()
    }
}

/// Built maps by map id, weighed in KiB so the budget is in bytes, not entries; with
/// `--data-dir`, backed by the maps on disk (a memory miss reads the disk, a new map is written
/// to both, a deleted one leaves both).
#[derive(Clone)]
pub struct MapCache {
    maps: moka::future::Cache<MapId, Arc<RadioMap>>,
    /// Each queried map's widest-path index ([`Bottlenecks`], 8 bytes a cell), built by its
    /// first path or sweep query. Its own budget, a quarter of the maps', holds the indexes of
    /// the maps being queried (an index is at most as big as its map); an evicted one is rebuilt
    /// on demand (≈ 0.1 s for 1001² cells). Map ids hash the map's inputs, so an index can never
    /// outlive the map it describes.
    indexes: moka::sync::Cache<MapId, Arc<Bottlenecks>>,
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
    pub fn new(budget_bytes: u64, disk: Option<MapDisk>) -> Self {
        // Least recently used, not moka's default TinyLFU: TinyLFU may refuse a new entry it
        // has seen once, and a map is requested once before it is built, so a map that was
        // just built (minutes of CPU) could be dropped at once while old ones stay.
        let maps = moka::future::Cache::builder()
            .eviction_policy(moka::policy::EvictionPolicy::lru())
            .max_capacity((budget_bytes / 1024).max(1))
            .weigher(|_id: &MapId, map: &Arc<RadioMap>| {
                (map.size_bytes() / 1024).clamp(1, u32::MAX as usize) as u32
            })
            .build();
        let indexes = moka::sync::Cache::builder()
            .eviction_policy(moka::policy::EvictionPolicy::lru())
            .max_capacity((budget_bytes / 4 / 1024).max(1))
            .weigher(|_id: &MapId, index: &Arc<Bottlenecks>| {
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

    /// The widest-path index of a cached map, built on first use by the calling thread (a query
    /// worker; concurrent first queries wait for one build).
    pub fn bottlenecks(&self, map_id: &MapId, map: &RadioMap) -> Arc<Bottlenecks> {
        self.indexes
            .get_with_by_ref(map_id, || Arc::new(planner::bottlenecks(map)))
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

    /// Drops a map from memory and disk; true if it was held.
    pub async fn remove(&self, map_id: &MapId) -> bool {
        let mut removed = self.maps.remove(map_id).await.is_some();
        self.indexes.invalidate(map_id);
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
                self.indexes.invalidate(&map_id);
            }
        }
        if let Some(disk) = &self.disk {
            disk.dir.remove_maps_of(scenario_id.as_str());
        }
        self.record_size();
    }

    /// The scenarios the cached maps were built from.
    pub fn scenario_ids(&self) -> HashSet<ScenarioId> {
        self.maps
            .iter()
            .map(|(_, m)| ScenarioId::of_key(&m.key))
            .collect()
    }
}
