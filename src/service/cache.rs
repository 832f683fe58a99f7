//! What the service keeps in memory: the scenario registry (bounded by count and by bytes,
//! least recently used API scenarios evicted first) and the map cache (moka, bounded by bytes
//! through a weigher, keyed by the map id = hash of the map key).

use super::auth::{Caller, Owner};
use super::errors::ApiError;
use crate::radiomap::RadioMap;
use crate::scenario::{Scenario, hash_hex};
use serde::Serialize;
use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, RwLock};

/// A registered scenario.
#[derive(Debug)]
pub struct StoredScenario {
    pub id: String,
    pub scenario: Arc<Scenario>,
    /// Where it came from: "builtin", "file", or "api". Only "api" scenarios are evicted or
    /// deleted: the others are the server's configuration.
    pub source: &'static str,
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
    pub id: String,
    pub name: Option<String>,
    pub source: &'static str,
    pub href: String,
}

impl StoredScenario {
    pub fn summary(&self) -> ScenarioSummary {
        ScenarioSummary {
            id: self.id.clone(),
            name: self.scenario.name.clone(),
            source: self.source,
            href: format!("/v1/scenarios/{}", self.id),
        }
    }

    /// May `caller` see it in a listing? The server's own scenarios are everybody's.
    fn visible_to(&self, caller: &Caller) -> bool {
        self.source != "api"
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
    by_id: RwLock<HashMap<String, Arc<StoredScenario>>>,
    clock: AtomicU64,
}

impl ScenarioRegistry {
    pub fn new(limit: usize, budget_bytes: usize) -> Self {
        ScenarioRegistry {
            limit,
            budget_bytes,
            by_id: RwLock::new(HashMap::new()),
            clock: AtomicU64::new(0),
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
        source: &'static str,
        owner: Option<Owner>,
        in_use: impl FnOnce() -> HashSet<String>,
    ) -> Result<(Arc<StoredScenario>, bool), ApiError> {
        // One canonical form for both the id and the weight (a floor plan's is megabytes).
        let canonical = scenario.canonical_json();
        let id = hash_hex(canonical.as_bytes());
        let bytes = canonical.len() + scenario.raster_bytes();
        let mut by_id = self.by_id.write().expect("registry lock");
        if let Some(existing) = by_id.get(&id) {
            existing.last_used.store(self.tick(), Ordering::Relaxed);
            if let Some(owner) = owner {
                existing.owners.lock().expect("owners lock").insert(owner);
            }
            return Ok((existing.clone(), false));
        }
        if bytes > self.budget_bytes {
            return Err(ApiError::registry_full(format!(
                "the scenario takes about {bytes} bytes, more than the registry's whole budget of {} bytes",
                self.budget_bytes
            )));
        }
        let mut held: usize = by_id.values().map(|s| s.bytes).sum();
        if by_id.len() >= self.limit || held + bytes > self.budget_bytes {
            let needed = in_use();
            let mut victims: Vec<(u64, String, usize)> = by_id
                .values()
                .filter(|s| s.source == "api" && !needed.contains(&s.id))
                .map(|s| (s.last_used.load(Ordering::Relaxed), s.id.clone(), s.bytes))
                .collect();
            victims.sort_unstable();
            let mut victims = victims.into_iter();
            while by_id.len() >= self.limit || held + bytes > self.budget_bytes {
                let Some((_, victim, freed)) = victims.next() else {
                    metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
                    return Err(ApiError::registry_full(format!(
                        "the registry holds {} scenarios in {held} bytes (limits: {} scenarios, \
                         {} bytes) and cached maps or live jobs need every one",
                        by_id.len(),
                        self.limit,
                        self.budget_bytes
                    )));
                };
                by_id.remove(&victim);
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
        Ok((stored, true))
    }

    pub fn get(&self, id: &str) -> Option<Arc<StoredScenario>> {
        let found = self.by_id.read().expect("registry lock").get(id).cloned();
        if let Some(s) = &found {
            s.last_used.store(self.tick(), Ordering::Relaxed);
        }
        found
    }

    /// Removes `caller`'s registration of an API scenario; the scenario goes with its last
    /// registration (true then). Built-in and preloaded files stay (409); a scenario the caller
    /// did not register is not found (404), as if it were not there.
    pub fn delete(&self, id: &str, caller: &Caller) -> Result<bool, ApiError> {
        let mut by_id = self.by_id.write().expect("registry lock");
        let Some(stored) = by_id.get(id) else {
            return Err(ApiError::not_found("scenario", id));
        };
        if stored.source != "api" {
            return Err(ApiError::scenario_protected(id, stored.source));
        }
        let gone = {
            let mut owners = stored.owners.lock().expect("owners lock");
            match caller {
                Caller::Open => true,
                Caller::Anonymous => return Err(ApiError::not_found("scenario", id)),
                Caller::Owner(me) => {
                    if !owners.remove(me) {
                        return Err(ApiError::not_found("scenario", id));
                    }
                    owners.is_empty()
                }
            }
        };
        if gone {
            by_id.remove(id);
            metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
            let held: usize = by_id.values().map(|s| s.bytes).sum();
            metrics::gauge!("irs_scenario_bytes").set(held as f64);
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

/// Built maps by map id, weighed in KiB so the budget is in bytes, not entries.
#[derive(Clone)]
pub struct MapCache {
    maps: moka::future::Cache<String, Arc<RadioMap>>,
}

impl MapCache {
    pub fn new(budget_bytes: u64) -> Self {
        // Least recently used, not moka's default TinyLFU: TinyLFU may refuse a new entry it
        // has seen once, and a map is requested once before it is built, so a map that was
        // just built (minutes of CPU) could be dropped at once while old ones stay.
        let maps = moka::future::Cache::builder()
            .eviction_policy(moka::policy::EvictionPolicy::lru())
            .max_capacity((budget_bytes / 1024).max(1))
            .weigher(|_id: &String, map: &Arc<RadioMap>| {
                (map.size_bytes() / 1024).clamp(1, u32::MAX as usize) as u32
            })
            .build();
        MapCache { maps }
    }

    /// Looks a map up, counting hits and misses.
    pub async fn get(&self, map_id: &str) -> Option<Arc<RadioMap>> {
        let found = self.maps.get(map_id).await;
        let outcome = if found.is_some() { "hit" } else { "miss" };
        metrics::counter!("irs_map_cache_requests_total", "outcome" => outcome).increment(1);
        found
    }

    pub async fn insert(&self, map_id: String, map: Arc<RadioMap>) {
        self.maps.insert(map_id, map).await;
        self.maps.run_pending_tasks().await;
        self.record_size();
    }

    pub fn record_size(&self) {
        metrics::gauge!("irs_map_cache_entries").set(self.maps.entry_count() as f64);
        metrics::gauge!("irs_map_cache_bytes").set((self.maps.weighted_size() * 1024) as f64);
    }

    /// The cached maps (id and map), for listing.
    pub fn entries(&self) -> Vec<(String, Arc<RadioMap>)> {
        self.maps.iter().map(|(k, v)| ((*k).clone(), v)).collect()
    }

    /// Drops a map; true if it was cached.
    pub async fn remove(&self, map_id: &str) -> bool {
        let removed = self.maps.remove(map_id).await.is_some();
        self.record_size();
        removed
    }

    /// The scenarios the cached maps were built from.
    pub fn scenario_ids(&self) -> HashSet<String> {
        self.maps
            .iter()
            .map(|(_, m)| m.key.scenario_id.clone())
            .collect()
    }
}
