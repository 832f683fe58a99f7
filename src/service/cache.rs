//! What the service keeps in memory: the scenario registry (bounded by count) and the map cache
//! (moka, bounded by bytes through a weigher, keyed by the map id = hash of the map key).

use super::errors::ApiError;
use crate::radiomap::RadioMap;
use crate::scenario::Scenario;
use serde::Serialize;
use std::collections::HashMap;
use std::sync::{Arc, RwLock};

/// A registered scenario.
#[derive(Debug)]
pub struct StoredScenario {
    pub id: String,
    pub scenario: Arc<Scenario>,
    /// Where it came from: "builtin", "file", or "api".
    pub source: &'static str,
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
pub struct ScenarioRegistry {
    limit: usize,
    by_id: RwLock<HashMap<String, Arc<StoredScenario>>>,
}

impl ScenarioRegistry {
    pub fn new(limit: usize) -> Self {
        ScenarioRegistry {
            limit,
            by_id: RwLock::new(HashMap::new()),
        }
    }

    /// Registers a validated scenario; returns it and whether it was new.
    pub fn register(
        &self,
        scenario: Scenario,
        source: &'static str,
    ) -> Result<(Arc<StoredScenario>, bool), ApiError> {
        let id = scenario.content_hash();
        let mut by_id = self.by_id.write().expect("registry lock");
        if let Some(existing) = by_id.get(&id) {
            return Ok((existing.clone(), false));
        }
        if by_id.len() >= self.limit {
            return Err(ApiError::registry_full(self.limit));
        }
        let stored = Arc::new(StoredScenario {
            id: id.clone(),
            scenario: Arc::new(scenario),
            source,
        });
        by_id.insert(id, stored.clone());
        metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
        Ok((stored, true))
    }

    pub fn get(&self, id: &str) -> Option<Arc<StoredScenario>> {
        self.by_id.read().expect("registry lock").get(id).cloned()
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
}
