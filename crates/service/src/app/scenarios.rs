//! Scenarios, wherever they are registered: this replica's registry first, then (in a
//! cluster) the shared store, whose scenarios are registered here on first use with their
//! owners. Handlers ask [`App::scenario`] or [`App::named_scenario`] and never look in the
//! registry and the store themselves, so no request can miss a scenario another replica holds
//! by asking in the wrong order.

use super::identity::Caller;
use super::queries::{INLINE_BYTES, json_weight};
use super::{App, Error, registrants};
use crate::app::registry::{ScenarioRecord, ScenarioSource, StoredScenario};
use crate::ids::ScenarioId;
use crate::store::Entry;
use irs_answers::scenario::ScenarioDocument as _;
use irs_model::scenario::Scenario;
use std::sync::Arc;

/// A scenario as a request names it: a registered one by id, or an inline document.
pub(crate) struct ScenarioRef {
    pub id: Option<ScenarioId>,
    pub document: Option<serde_json::Map<String, serde_json::Value>>,
}

/// The scenario a request named, found: its id, the scenario, and whether it came inline (it
/// is then registered only once the whole request has been validated).
pub(crate) struct Named {
    pub id: ScenarioId,
    pub scenario: Arc<Scenario>,
    pub inline: bool,
}

/// A scenario document embedded in a request at `prefix` (e.g. `"map.scenario."`).
pub(crate) fn parse_scenario(value: serde_json::Value, prefix: &str) -> Result<Scenario, Error> {
    Scenario::from_value(value).map_err(|e| Error::InvalidScenario(e.within(prefix)))
}

impl App {
    /// A scenario by id: registered here, or (in a cluster) registered on another replica,
    /// which registers it here too with its owners. `Ok(None)`: nowhere; unavailable while the
    /// shared store is down and the scenario is not here.
    pub(crate) async fn scenario(
        &self,
        id: &ScenarioId,
    ) -> Result<Option<Arc<StoredScenario>>, Error> {
        if let Some(stored) = self.registry().get(id) {
            return Ok(Some(stored));
        }
        let Some(record) = self
            .store()
            .record::<ScenarioRecord>(Entry::Scenario(id))
            .await?
        else {
            return Ok(None);
        };
        let weight = json_weight(&record.document, INLINE_BYTES);
        let (document, expected) = (record.document, id.clone());
        let parsed = self
            .queries()
            .run_sized("scenario", weight, move || {
                let scenario = Scenario::from_json(&document.to_string())
                    .map_err(|e| format!("not a scenario of this build: {e}"))?;
                if ScenarioId::of(&scenario) != expected {
                    return Err("its document has another id in this build".to_string());
                }
                Ok(Arc::new(scenario))
            })
            .await?;
        // A record no replica of this build could have written: deleted, so the scenario is
        // unknown (registered again by whoever has it) rather than a 500 on every request.
        let scenario = match parsed {
            Ok(scenario) => scenario,
            Err(why) => {
                self.store().discard(Entry::Scenario(id), &why).await;
                return Ok(None);
            }
        };
        let mut stored = None;
        for owner in registrants(record.owners) {
            stored = Some(
                self.register_api_scenario(scenario.clone(), &owner)
                    .await?
                    .0,
            );
        }
        Ok(stored)
    }

    /// A scenario by id as `caller` may see it: the server's own scenarios are everybody's, an
    /// API scenario only its registrants' (anybody else is told it does not exist).
    pub(crate) async fn visible_scenario(
        &self,
        caller: &Caller,
        id: &ScenarioId,
    ) -> Result<Option<Arc<StoredScenario>>, Error> {
        Ok(self.scenario(id).await?.filter(|s| s.visible_to(caller)))
    }

    /// The scenario a request of `caller` names at `prefix`: a registered one by id that the
    /// caller may see (here or on another replica; an unknown id is "not found", as an unknown
    /// map id is, naming the field) or an inline document (parsed, not registered yet).
    pub(crate) async fn named_scenario(
        &self,
        caller: &Caller,
        reference: ScenarioRef,
        prefix: &str,
    ) -> Result<Named, Error> {
        match (reference.id, reference.document) {
            (Some(id), None) => {
                let stored = self.visible_scenario(caller, &id).await?.ok_or_else(|| {
                    Error::not_found("scenario", &id).with_field(format!("{prefix}scenario_id"))
                })?;
                Ok(Named {
                    id,
                    scenario: stored.scenario.clone(),
                    inline: false,
                })
            }
            (None, Some(doc)) => {
                let document = serde_json::Value::Object(doc);
                let weight = json_weight(&document, INLINE_BYTES);
                let prefix = format!("{prefix}scenario.");
                let (id, scenario) = self
                    .queries()
                    .run_sized("scenario", weight, move || {
                        let scenario = parse_scenario(document, &prefix)?;
                        Ok::<_, Error>((ScenarioId::of(&scenario), Arc::new(scenario)))
                    })
                    .await??;
                Ok(Named {
                    id,
                    scenario,
                    inline: true,
                })
            }
            _ => Err(Error::invalid(
                format!("{prefix}scenario_id"),
                "give exactly one of scenario_id (a registered scenario) and scenario (an inline document)",
            )),
        }
    }

    /// Registers a scenario sent to the API for `caller` and, in a cluster, publishes it (its
    /// document and owners) for the other replicas. Returns it and whether it was new.
    /// The document is parsed (its floor plan decoded) on the query pool when it is big.
    pub(crate) async fn add_scenario(
        &self,
        document: serde_json::Value,
        caller: &Caller,
    ) -> Result<(Arc<StoredScenario>, bool), Error> {
        let weight = json_weight(&document, INLINE_BYTES);
        let scenario = self
            .queries()
            .run_sized("scenario", weight, move || parse_scenario(document, ""))
            .await??;
        let (stored, created) = self
            .register_api_scenario(Arc::new(scenario), caller)
            .await?;
        self.share_scenario(&stored, true).await?;
        Ok((stored, created))
    }

    /// Publishes an API scenario (document and owners) for the other replicas (nothing on a
    /// lone node); `replace` false leaves a record already there as it is (see
    /// [`crate::store::Store::put_scenario`]).
    pub(super) async fn share_scenario(
        &self,
        stored: &StoredScenario,
        replace: bool,
    ) -> Result<(), Error> {
        if stored.source != ScenarioSource::Api {
            return Ok(());
        }
        // Written only by a store that shares it: a floor plan's record is megabytes.
        let record = || serde_json::to_vec(&stored.record()).expect("records serialise");
        Ok(self
            .store()
            .put_scenario(&stored.id, &record, replace)
            .await?)
    }

    /// Deletes the caller's registration of an API scenario; with the last registration the
    /// scenario goes, with the maps built from it, here, in the shared store and (told through
    /// it) on every other replica. Any replica can delete it: one that has not loaded it yet
    /// reads it from the store first. A scenario that a queued or running job needs is kept
    /// (in use, with the job).
    pub(crate) async fn delete_scenario(
        &self,
        id: &ScenarioId,
        caller: &Caller,
    ) -> Result<(), Error> {
        if let Some(job) = self
            .jobs()
            .live()
            .into_iter()
            .find(|j| j.scenario_id == *id)
        {
            return Err(Error::ScenarioInUse {
                id: id.clone(),
                job_id: job.id.clone(),
            });
        }
        // Loaded here if another replica registered it, so the caller's registration is seen.
        self.scenario(id).await?;
        if self.registry().delete(id, caller)? {
            self.cache().remove_scenario_maps(id).await;
            self.store().delete(Entry::Scenario(id)).await?;
            tracing::info!(scenario_id = %id, "scenario deleted");
        }
        Ok(())
    }
}
