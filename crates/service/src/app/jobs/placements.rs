//! Placement jobs: a checked search ranked on the blocking pool, its best candidates
//! registered with their maps cached, and the answer kept in the job.

use super::Jobs;
use super::job::{Job, Work};
use crate::app::Error;
use crate::app::cache::MapCache;
use crate::app::identity::Owner;
use crate::ids::{MapId, ScenarioId};
use irs_model::placement::{self, Candidate, Placement, Search};
use irs_model::radiomap::{Cancelled, MapKey, Progress, RadioMap, WorkError};
use irs_model::scenario::Scenario;
use std::sync::{Arc, OnceLock};
use tracing::Instrument;

/// Claiming a candidate's map for the search's owner (which may ask the shared store).
pub type Claiming = std::pin::Pin<Box<dyn std::future::Future<Output = ()> + Send>>;

/// A checked placement search, ready to run.
pub struct PlacementSearch {
    pub scenario: Arc<Scenario>,
    pub search: Search,
    /// Its candidates, checked by [`placement::candidates`].
    pub candidates: Vec<Candidate>,
    /// How many of the best to register with their maps.
    pub keep: usize,
}

/// A finished placement search: the answer, and how many of its best candidates were
/// registered with their maps cached (fewer than asked only if the registry refused some).
pub struct PlacementOutcome {
    /// The [`placement::PlacementAnswer`] as JSON: what the API answers, and what a data
    /// directory keeps.
    pub answer: serde_json::Value,
    pub registered: usize,
    /// What the answer weighs in the job history (`--job-history-mb`): its JSON text's length,
    /// about what the JSON value holds in memory.
    pub bytes: usize,
}

impl PlacementOutcome {
    pub fn new(answer: serde_json::Value, registered: usize) -> Self {
        let bytes = serde_json::to_vec(&answer).map_or(0, |text| text.len());
        PlacementOutcome {
            answer,
            registered,
            bytes,
        }
    }
}

impl Jobs {
    /// Starts a placement search as a job (503 when the queue is full). When it is done, the
    /// best `keep` candidates' scenarios go to `register`, their maps to `claim` (for the
    /// owner) and into `cache`, so the
    /// answer's map ids answer path queries at once; then the answer is kept in the job.
    pub fn place(
        self: &Arc<Self>,
        cache: &MapCache,
        search: PlacementSearch,
        owner: Option<Owner>,
        register: impl Fn(Scenario) -> bool + Send + 'static,
        claim: impl Fn(MapId) -> Claiming + Send + 'static,
    ) -> Result<Arc<Job>, Error> {
        let PlacementSearch {
            scenario,
            search,
            candidates,
            keep,
        } = search;
        self.check_room()?;
        let job = self.admit(
            ScenarioId::of(&scenario),
            owner,
            Work::Placement {
                outcome: OnceLock::new(),
            },
        );
        metrics::counter!("irs_placements_total").increment(1);
        let span = tracing::info_span!("job", job_id = %job.id, kind = "placement", scenario_id = %job.scenario_id);
        let progress = job.progress.clone();
        let work = move || -> Result<(Placement, Vec<RadioMap>), WorkError> {
            let placement = placement::rank_candidates(
                &scenario,
                &search,
                candidates,
                &irs_answers::map::ContentIds,
                &progress,
            )?;
            let phases = placement.answer.phases;
            // The best candidates' maps, built now so their ids answer at once (gain maps of
            // the search's floor: milliseconds each).
            let maps = placement
                .scenarios
                .iter()
                .take(keep)
                .map(|s| {
                    if progress.is_cancelled() {
                        return Err(Cancelled.into());
                    }
                    let key = MapKey::gain(ScenarioId::of(s).as_str(), s, phases)?;
                    Ok(irs_answers::map::build(s, &key, &Progress::default())?)
                })
                .collect::<Result<Vec<_>, WorkError>>()?;
            Ok((placement, maps))
        };
        let cache = cache.clone();
        let finish = move |job: Arc<Job>, (placement, maps): (Placement, Vec<RadioMap>)| async move {
            let mut registered = 0;
            for (scenario, map) in placement.scenarios.into_iter().zip(maps) {
                if register(scenario) {
                    let map_id = MapId::of_map(&map);
                    claim(map_id.clone()).await;
                    cache.insert(map_id, Arc::new(map)).await;
                    registered += 1;
                }
            }
            if let Work::Placement { outcome } = &job.work {
                let answer = serde_json::to_value(&placement.answer).expect("answers serialise");
                let _ = outcome.set(Arc::new(PlacementOutcome::new(answer, registered)));
            }
        };
        crate::tasks::spawn(self.clone().run(job.clone(), work, finish).instrument(span));
        Ok(job)
    }
}
