//! What the service keeps in memory: the scenario registry (bounded by count, least recently
//! used API scenarios evicted first) and the map cache (moka, bounded by bytes through a
//! weigher, keyed by the map id = hash of the map key).

use super::errors::ApiError;
use crate::radiomap::RadioMap;
use crate::scenario::Scenario;
use serde::Serialize;
use std::collections::{HashMap, HashSet};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};

/// A registered scenario.
#[derive(Debug)]
pub struct StoredScenario {
    pub id: String,
    pub scenario: Arc<Scenario>,
    /// Where it came from: "builtin", "file", or "api". Only "api" scenarios are evicted or
    /// deleted: the others are the server's configuration.
    pub source: &'static str,
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
}

/// Scenarios by content hash; registering the same document twice is idempotent.
///
/// Inline scenarios in map requests are registered too, so without eviction a stream of them
/// would fill the registry for good. When it is full, a new scenario replaces the least
/// recently used one registered through the API that no cached map and no live job needs;
/// only when there is none is the registration refused (507).
pub struct ScenarioRegistry {
    limit: usize,
    by_id: RwLock<HashMap<String, Arc<StoredScenario>>>,
    clock: AtomicU64,
}

impl ScenarioRegistry {
    pub fn new(limit: usize) -> Self {
        ScenarioRegistry {
            limit,
            by_id: RwLock::new(HashMap::new()),
            clock: AtomicU64::new(0),
        }
    }

    fn tick(&self) -> u64 {
        self.clock.fetch_add(1, Ordering::Relaxed)
    }

    /// Registers a validated scenario; returns it and whether it was new. `in_use` lists the
    /// scenarios that cached maps or live jobs need; it is asked only when the registry is full.
    pub fn register(
        &self,
        scenario: Scenario,
        source: &'static str,
        in_use: impl FnOnce() -> HashSet<String>,
    ) -> Result<(Arc<StoredScenario>, bool), ApiError> {
        let id = scenario.content_hash();
        let mut by_id = self.by_id.write().expect("registry lock");
        if let Some(existing) = by_id.get(&id) {
            existing.last_used.store(self.tick(), Ordering::Relaxed);
            return Ok((existing.clone(), false));
        }
        if by_id.len() >= self.limit {
            let needed = in_use();
            let victim = by_id
                .values()
                .filter(|s| s.source == "api" && !needed.contains(&s.id))
                .min_by_key(|s| s.last_used.load(Ordering::Relaxed))
                .map(|s| s.id.clone())
                .ok_or_else(|| ApiError::registry_full(self.limit))?;
            by_id.remove(&victim);
            metrics::counter!("irs_scenarios_evicted_total").increment(1);
            tracing::info!(scenario_id = %victim, "least recently used scenario evicted");
        }
        let stored = Arc::new(StoredScenario {
            id: id.clone(),
            scenario: Arc::new(scenario),
            source,
            last_used: AtomicU64::new(self.tick()),
        });
        by_id.insert(id, stored.clone());
        metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
        Ok((stored, true))
    }

    pub fn get(&self, id: &str) -> Option<Arc<StoredScenario>> {
        let found = self.by_id.read().expect("registry lock").get(id).cloned();
        if let Some(s) = &found {
            s.last_used.store(self.tick(), Ordering::Relaxed);
        }
        found
    }

    /// Removes an API-registered scenario; builtin and preloaded files stay (409).
    pub fn delete(&self, id: &str) -> Result<Arc<StoredScenario>, ApiError> {
        let mut by_id = self.by_id.write().expect("registry lock");
        match by_id.get(id) {
            None => Err(ApiError::not_found("scenario", id)),
            Some(s) if s.source != "api" => Err(ApiError::scenario_protected(id, s.source)),
            Some(_) => {
                let removed = by_id.remove(id).expect("present");
                metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
                Ok(removed)
            }
        }
    }

    pub fn list(&self) -> Vec<ScenarioSummary> {
        let mut all: Vec<ScenarioSummary> = self
            .by_id
            .read()
            .expect("registry lock")
            .values()
            .map(|s| s.summary())
            .collect();
        all.sort_by(|a, b| (&a.name, &a.id).cmp(&(&b.name, &b.id)));
        all
    }
}

/// Built maps by map id, weighed in KiB so the budget is in bytes, not entries.
#[derive(Clone)]
pub struct MapCache {
    maps: moka::future::Cache<String, Arc<RadioMap>>,
}

impl MapCache {
    pub fn new(budget_bytes: u64) -> Self {
        let maps = moka::future::Cache::builder()
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

    /// Looks a map up without counting (single-flight bookkeeping).
    pub async fn peek(&self, map_id: &str) -> Option<Arc<RadioMap>> {
        self.maps.get(map_id).await
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
