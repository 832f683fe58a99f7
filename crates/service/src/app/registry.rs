//! The scenario registry: the scenarios this replica knows, by content hash, bounded by count
//! and by bytes (least recently used API scenarios evicted first), with where each came from
//! and who registered it; and [`ScenarioRecord`], what the data directory and the shared store
//! keep of an API scenario.

use crate::app::Error;
use crate::app::identity::{Caller, Owner};
use crate::ids::ScenarioId;
use crate::store::{DataDir, Kind};
use irs_answers::scenario::ScenarioDocument as _;
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

    /// Who holds it, for the fair share: its owners, or nobody in particular.
    fn holders(&self) -> Vec<Option<Owner>> {
        let owners = self.owners.lock().expect("owners lock");
        if owners.is_empty() {
            vec![None]
        } else {
            owners.iter().cloned().map(Some).collect()
        }
    }

    /// May `caller` see it (in a listing, or by id)? The server's own scenarios are
    /// everybody's; an API scenario only its registrants'.
    pub fn visible_to(&self, caller: &Caller) -> bool {
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
/// would fill the registry for good, and if cached maps pinned their scenarios one client
/// could lock every other out with a thousand tiny maps. So when it is full (by count or by
/// bytes), API scenarios are evicted by fair share, together with the maps built from them;
/// only scenarios live jobs need are kept ([`ScenarioRegistry::register`]).
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

/// What a registration did: the scenario, whether it is new to the caller, and the scenarios
/// evicted to make room (their maps are to go too).
pub struct Registered {
    pub stored: Arc<StoredScenario>,
    pub created: bool,
    pub evicted: Vec<ScenarioId>,
}

/// Who holds how many API scenarios: each owner of a scenario holds it (`None`: registered
/// with authentication off, held by nobody in particular).
struct Shares(HashMap<Option<Owner>, usize>);

impl Shares {
    /// The holdings now, the caller's counting the scenario it registers.
    fn of(by_id: &HashMap<ScenarioId, Arc<StoredScenario>>, caller: &Option<Owner>) -> Shares {
        let mut held: HashMap<Option<Owner>, usize> = HashMap::new();
        for s in by_id.values().filter(|s| s.source == ScenarioSource::Api) {
            for holder in s.holders() {
                *held.entry(holder).or_default() += 1;
            }
        }
        *held.entry(caller.clone()).or_default() += 1;
        Shares(held)
    }

    /// A holder's count.
    fn of_holder(&self, holder: &Option<Owner>) -> usize {
        self.0.get(holder).copied().unwrap_or(0)
    }

    /// Whether `holder` holds more than an equal share of `room` among the current holders.
    fn over_share(&self, holder: &Option<Owner>, room: usize) -> bool {
        let share = room / self.0.len().max(1);
        self.of_holder(holder) > share.max(1)
    }

    /// The scenario to evict for `caller`: of the API scenarios no live job needs, the one
    /// whose heaviest holder holds the most, the least recently used first; a scenario only
    /// that holder holds goes before one it shares with others. Never one of a holder that
    /// holds fewer than the caller: a client over its share makes room from its own.
    fn victim(
        &self,
        by_id: &HashMap<ScenarioId, Arc<StoredScenario>>,
        pinned: &HashSet<ScenarioId>,
        caller: &Option<Owner>,
    ) -> Option<ScenarioId> {
        let floor = self.of_holder(caller);
        by_id
            .values()
            .filter(|s| s.source == ScenarioSource::Api && !pinned.contains(&s.id))
            .filter_map(|s| {
                let holders = s.holders();
                let heaviest = holders.iter().map(|h| self.of_holder(h)).max().unwrap_or(0);
                (heaviest >= floor).then_some(s)?;
                Some((
                    std::cmp::Reverse(heaviest),
                    holders.len(),
                    s.last_used.load(Ordering::Relaxed),
                    s.id.clone(),
                ))
            })
            .min()
            .map(|(_, _, _, id)| id)
    }
}

/// A scenario as the data directory (`scenarios/<id>.rec`) and the shared store
/// (`irs:scenario:<id>`) keep it. Persisted: a field added must default when absent, so that
/// records written before it stay readable.
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

    /// Registers a validated scenario for `owner`. `pinned` lists the scenarios live jobs
    /// need; it is asked only when the registry is full.
    ///
    /// Full (by count or bytes), the registry evicts API scenarios by fair share: the holder
    /// (an owner, or nobody with authentication off) registered on the most scenarios loses
    /// its least recently used one first, so one client's flood evicts its own scenarios and
    /// never locks out the others. Scenarios a live job needs are not evicted; when only those
    /// are left, a caller over its fair share is refused (507), and one within its share is
    /// admitted over the limit by at most as many scenarios as are pinned (workers + queue).
    pub fn register(
        &self,
        scenario: Scenario,
        source: ScenarioSource,
        owner: Option<Owner>,
        pinned: impl FnOnce() -> HashSet<ScenarioId>,
    ) -> Result<Registered, Error> {
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
            // A tenant that did not have it is answered as if it were new: content-hash ids must
            // not tell one tenant what another registered.
            let created = added && existing.source == ScenarioSource::Api;
            return Ok(Registered {
                stored: existing,
                created,
                evicted: Vec::new(),
            });
        }
        if bytes > self.budget_bytes {
            metrics::counter!("irs_scenarios_refused_total", "why" => "too_large").increment(1);
            return Err(Error::RegistryFull {
                detail: format!(
                    "the scenario takes about {bytes} bytes, more than the registry's whole budget of {} bytes",
                    self.budget_bytes
                ),
                retry: false,
            });
        }
        let mut held: usize = by_id.values().map(|s| s.bytes).sum();
        let mut evicted = Vec::new();
        if by_id.len() >= self.limit || held + bytes > self.budget_bytes {
            let pinned = pinned();
            let holder = owner.clone();
            loop {
                if by_id.len() < self.limit && held + bytes <= self.budget_bytes {
                    break;
                }
                let shares = Shares::of(&by_id, &holder);
                match shares.victim(&by_id, &pinned, &holder) {
                    Some(victim) => {
                        if let Some(gone) = by_id.remove(&victim) {
                            held -= gone.bytes;
                        }
                        self.unpersist(&victim);
                        metrics::counter!("irs_scenarios_evicted_total").increment(1);
                        tracing::info!(scenario_id = %victim, "scenario evicted (fair share) with its maps");
                        evicted.push(victim);
                    }
                    None => {
                        // Only scenarios live jobs need are left to evict.
                        let (pinned_count, pinned_bytes) = by_id
                            .values()
                            .filter(|s| pinned.contains(&s.id))
                            .fold((0, 0), |(n, b), s| (n + 1, b + s.bytes));
                        let over_share = shares.over_share(&holder, self.api_limit(&by_id));
                        let overshoot_left = by_id.len() < self.limit.saturating_add(pinned_count)
                            && held + bytes <= self.budget_bytes.saturating_add(pinned_bytes);
                        if !over_share && overshoot_left {
                            break;
                        }
                        let why = if over_share { "over_share" } else { "full" };
                        metrics::counter!("irs_scenarios_refused_total", "why" => why).increment(1);
                        metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
                        return Err(Error::RegistryFull {
                            detail: format!(
                                "the registry holds {} scenarios in {held} bytes (limits: {} scenarios, \
                             {} bytes); {} and live jobs need every one that could make room: \
                             retry when a job ends, or delete scenarios you registered",
                                by_id.len(),
                                self.limit,
                                self.budget_bytes,
                                if over_share {
                                    "you hold more than your fair share"
                                } else {
                                    "the registry is full"
                                }
                            ),
                            retry: true,
                        });
                    }
                }
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
        Ok(Registered {
            stored,
            created: true,
            evicted,
        })
    }

    /// Room for API scenarios: the count limit less the server's own scenarios.
    fn api_limit(&self, by_id: &HashMap<ScenarioId, Arc<StoredScenario>>) -> usize {
        let own = by_id
            .values()
            .filter(|s| s.source != ScenarioSource::Api)
            .count();
        self.limit.saturating_sub(own)
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
            self.remove(&mut by_id, id);
        } else {
            let stored = stored.clone();
            drop(by_id);
            self.persist(&stored);
        }
        Ok(gone)
    }

    /// Forgets an API scenario whoever registered it (another replica deleted it with its last
    /// registration); true if it was here. The server's own scenarios stay.
    pub fn forget(&self, id: &ScenarioId) -> bool {
        let mut by_id = self.by_id.write().expect("registry lock");
        if by_id
            .get(id)
            .is_none_or(|s| s.source != ScenarioSource::Api)
        {
            return false;
        }
        self.remove(&mut by_id, id);
        true
    }

    fn remove(&self, by_id: &mut HashMap<ScenarioId, Arc<StoredScenario>>, id: &ScenarioId) {
        by_id.remove(id);
        self.unpersist(id);
        metrics::gauge!("irs_scenarios").set(by_id.len() as f64);
        let held: usize = by_id.values().map(|s| s.bytes).sum();
        metrics::gauge!("irs_scenario_bytes").set(held as f64);
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

#[cfg(test)]
mod tests {
    use super::*;

    fn floor(name: &str) -> Scenario {
        let mut scenario = Scenario::builtin("small-test").unwrap();
        scenario.name = Some(name.to_string());
        scenario
    }

    fn owner(digest: &str) -> Option<Owner> {
        Some(Owner::from_digest(digest.into()))
    }

    /// The registry's API scenarios, by name.
    fn names(registry: &ScenarioRegistry) -> Vec<String> {
        let mut names: Vec<String> = registry
            .list(&Caller::Open)
            .into_iter()
            .filter(|s| s.source == ScenarioSource::Api)
            .filter_map(|s| s.name)
            .collect();
        names.sort();
        names
    }

    #[test]
    fn a_flood_evicts_its_own_and_a_full_registry_refuses_only_its_filler() {
        let registry = ScenarioRegistry::new(4, usize::MAX, None);
        let none = HashSet::new;
        let (a, b) = (owner("aaaa"), owner("bbbb"));
        registry
            .register(floor("b0"), ScenarioSource::Api, b.clone(), none)
            .unwrap();
        for k in 0..10 {
            let done = registry.register(
                floor(&format!("a{k}")),
                ScenarioSource::Api,
                a.clone(),
                none,
            );
            assert!(done.unwrap().created, "a's flood is admitted: {k}");
        }
        assert_eq!(
            names(&registry),
            ["a7", "a8", "a9", "b0"],
            "a evicted its own, oldest first"
        );
        // B, under its share, makes room from the heaviest holder.
        let b1 = registry
            .register(floor("b1"), ScenarioSource::Api, b.clone(), none)
            .unwrap();
        assert_eq!(b1.evicted.len(), 1);
        assert_eq!(names(&registry), ["a8", "a9", "b0", "b1"]);
        // Every scenario of a's pinned by live jobs: a, over its share, is refused (and may
        // not evict b's), b is admitted over the limit by at most the pinned ones.
        let pinned = || -> HashSet<ScenarioId> {
            ["a8", "a9"]
                .iter()
                .map(|n| ScenarioId::of(&floor(n)))
                .collect()
        };
        let refused = registry.register(floor("a10"), ScenarioSource::Api, a.clone(), pinned);
        assert!(
            matches!(refused, Err(Error::RegistryFull { retry: true, .. })),
            "a is refused"
        );
        // b at its share: its own oldest goes first.
        let b2 = registry
            .register(floor("b2"), ScenarioSource::Api, b.clone(), pinned)
            .unwrap();
        assert_eq!(b2.evicted, [ScenarioId::of(&floor("b0"))]);
        // The same document is new to another tenant, and not to its registrant.
        let again = registry
            .register(floor("b2"), ScenarioSource::Api, a, pinned)
            .unwrap();
        assert!(again.created && again.evicted.is_empty());
        let twice = registry
            .register(floor("b2"), ScenarioSource::Api, b, pinned)
            .unwrap();
        assert!(!twice.created);
    }
}
