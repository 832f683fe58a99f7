//! A job as the API shows it ([`JobView`]) and as the data directory and Redis keep it
//! ([`JobRecord`], persisted: records written by earlier releases must stay readable, so a
//! field added must default when absent); and a [`Job`] turned into each and back.

use super::answers::{AnswerKind, AnswerOutcome};
use super::job::{Job, JobKind, JobState, JobTimes, MapDelivery, Work, from_unix, unix};
use super::placements::PlacementOutcome;
use crate::app::identity::{Owner, Owners};
use crate::ids::{JobId, MapId, ScenarioId};
use irs_model::radiomap::{MapKey, Progress};
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::SystemTime;
use tokio::sync::{Notify, watch};

/// A job as the API shows it, and the part of its record that says so: the fields here are
/// the facts a record keeps (read back with serde's derive, so a record from any release that
/// has them is readable); what follows from them (`kind`, `map_id`, `progress` and the links)
/// is added when the view is written (its `Serialize`, below).
#[derive(Debug, Clone, Deserialize)]
pub struct JobView {
    pub job_id: JobId,
    /// The kind as recorded; records written before checks existed have none, and their kind
    /// follows from `key` ([`JobView::kind`]).
    #[serde(default, rename = "kind")]
    pub recorded_kind: Option<JobKind>,
    pub scenario_id: ScenarioId,
    /// Map jobs: the key of the map being built (null for placements; its hash is the map id).
    pub key: Option<MapKey>,
    pub state: JobState,
    pub cells_done: usize,
    pub cells_total: usize,
    pub created_at: f64,
    pub started_at: Option<f64>,
    pub finished_at: Option<f64>,
    pub error: Option<String>,
}

impl JobView {
    pub fn kind(&self) -> JobKind {
        self.recorded_kind.unwrap_or(match self.key {
            Some(_) => JobKind::Map,
            None => JobKind::Placement,
        })
    }

    /// cells_done / cells_total (0 before the build starts).
    pub fn progress(&self) -> f64 {
        if self.cells_total == 0 {
            0.0
        } else {
            self.cells_done as f64 / self.cells_total as f64
        }
    }
}

/// The API's `Job` (openapi.yaml): the view's fields with what follows from them, in this order.
impl Serialize for JobView {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct as _;
        let map_id = self.key.as_ref().map(MapId::of);
        let result_href = match (self.kind(), &map_id) {
            (JobKind::Map, Some(map_id)) => map_id.href(),
            (JobKind::Check, _) => AnswerKind::Check.href(&self.job_id),
            (JobKind::Fleet, _) => AnswerKind::Fleet.href(&self.job_id),
            _ => self.job_id.placement_href(),
        };
        let mut job = serializer.serialize_struct("JobView", 15)?;
        job.serialize_field("job_id", &self.job_id)?;
        job.serialize_field("kind", &self.kind())?;
        job.serialize_field("scenario_id", &self.scenario_id)?;
        job.serialize_field("map_id", &map_id)?;
        job.serialize_field("key", &self.key)?;
        job.serialize_field("state", &self.state)?;
        job.serialize_field("cells_done", &self.cells_done)?;
        job.serialize_field("cells_total", &self.cells_total)?;
        job.serialize_field("progress", &self.progress())?;
        job.serialize_field("created_at", &self.created_at)?;
        job.serialize_field("started_at", &self.started_at)?;
        job.serialize_field("finished_at", &self.finished_at)?;
        job.serialize_field("error", &self.error)?;
        job.serialize_field("href", &self.job_id.href())?;
        // Where the result is read once the job is done: the map, the placement answer or the
        // checked path.
        job.serialize_field("result_href", &result_href)?;
        job.end()
    }
}

/// A job as the data directory (`serve --data-dir`, finished jobs) and Redis (a cluster's map
/// builds, while they run and after) keep it: its view, and what it takes to list, authorise
/// and, for a placement, answer it again.
#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct JobRecord {
    #[serde(flatten)]
    pub view: JobView,
    pub seq: u64,
    /// The first owner's digest (never the token): what records had before `owners`, kept so
    /// an older release reads the record.
    pub owner: Option<String>,
    /// Every owner's digest (a shared build serves several tenants). Absent from older
    /// records: `owner` alone then.
    #[serde(default)]
    pub owners: Vec<String>,
    /// Placement jobs that finished: the answer and how many candidates were registered.
    pub placement: Option<(serde_json::Value, usize)>,
    /// Check jobs that finished: the checked path's answer. Absent from older records.
    #[serde(default)]
    pub check: Option<serde_json::Value>,
    /// Fleet-plan jobs that finished: the plan. Absent from older records.
    #[serde(default)]
    pub fleet: Option<serde_json::Value>,
}

impl JobRecord {
    /// A map job not started yet, as the replica that takes a request records it.
    pub(crate) fn queued(key: &MapKey, owner: Option<&Owner>) -> JobRecord {
        JobRecord {
            view: JobView {
                job_id: JobId::random(),
                recorded_kind: Some(JobKind::Map),
                scenario_id: ScenarioId::of_key(key),
                key: Some(key.clone()),
                state: JobState::Queued,
                cells_done: 0,
                cells_total: 0,
                created_at: unix(Some(SystemTime::now())).unwrap_or(0.0),
                started_at: None,
                finished_at: None,
                error: None,
            },
            seq: 0,
            owner: owner.map(|o| o.to_string()),
            owners: owner.map(|o| o.to_string()).into_iter().collect(),
            placement: None,
            check: None,
            fleet: None,
        }
    }

    /// The owners, from `owners`, or `owner` in a record written before it.
    pub(crate) fn owners(&self) -> Owners {
        if self.owners.is_empty() {
            Owners::from_digests(self.owner.clone())
        } else {
            Owners::from_digests(self.owners.clone())
        }
    }
}

impl Job {
    pub fn view(&self) -> JobView {
        let times = *self.times.lock().expect("job lock");
        JobView {
            job_id: self.id.clone(),
            recorded_kind: Some(self.kind()),
            scenario_id: self.scenario_id.clone(),
            key: match &self.work {
                Work::Map { key, .. } => Some(key.clone()),
                Work::Placement { .. } | Work::Answer { .. } => None,
            },
            state: self.state(),
            cells_done: self.progress.cells_done(),
            cells_total: self.progress.cells_total(),
            created_at: unix(times.created).unwrap_or(0.0),
            started_at: unix(times.started),
            finished_at: unix(times.finished),
            error: self.error.lock().expect("job lock").clone(),
        }
    }

    /// The record of this job as it ends in `ended`, written before the job is seen to end:
    /// its finish time is taken now, and [`Job::set_state`] keeps it.
    pub(super) fn record_as(&self, ended: JobState) -> JobRecord {
        self.times.lock().expect("job lock").finished = Some(SystemTime::now());
        let mut record = self.record();
        record.view.state = ended;
        record
    }

    /// The record a data directory keeps of a finished job (and Redis of a cluster's build).
    pub(crate) fn record(&self) -> JobRecord {
        let owners = self.owners();
        JobRecord {
            view: self.view(),
            seq: self.seq,
            owner: owners.first().map(|o| o.to_string()),
            owners: owners.digests(),
            placement: self
                .placement()
                .map(|outcome| (outcome.answer.clone(), outcome.registered)),
            check: self
                .answer(AnswerKind::Check)
                .map(|outcome| outcome.answer.clone()),
            fleet: self
                .answer(AnswerKind::Fleet)
                .map(|outcome| outcome.answer.clone()),
        }
    }

    /// The record of a build the shutdown interrupted, as the next start resumes it: queued
    /// again, with no start or end.
    pub(super) fn record_interrupted(&self) -> JobRecord {
        let mut record = self.record();
        record.view.state = JobState::Queued;
        record.view.started_at = None;
        record.view.finished_at = None;
        record.view.cells_done = 0;
        record
    }

    /// A finished job again, from its record; `None` for a record that is not of a finished
    /// job (the store only writes finished ones) or whose map key does not match its kind.
    pub(super) fn restore(record: JobRecord) -> Option<Job> {
        let owners = record.owners();
        let JobRecord {
            view,
            seq,
            placement,
            check,
            fleet,
            ..
        } = record;
        if !view.state.is_terminal() {
            return None;
        }
        let answered = |kind, answer: Option<serde_json::Value>| {
            let outcome = OnceLock::new();
            if let Some(answer) = answer {
                let _ = outcome.set(Arc::new(AnswerOutcome::new(answer)));
            }
            Work::Answer { kind, outcome }
        };
        let work = match (view.kind(), view.key, placement, check, fleet) {
            (JobKind::Map, Some(key), None, None, None) => Work::Map {
                map_id: MapId::of(&key),
                key,
                delivery: Mutex::new(MapDelivery::default()),
                resumable: false,
                checkpoint: Arc::default(),
            },
            (JobKind::Placement, None, placement, None, None) => {
                let outcome = OnceLock::new();
                if let Some((answer, registered)) = placement {
                    let _ = outcome.set(Arc::new(PlacementOutcome::new(answer, registered)));
                }
                Work::Placement { outcome }
            }
            (JobKind::Check, None, None, check, None) => answered(AnswerKind::Check, check),
            (JobKind::Fleet, None, None, None, fleet) => answered(AnswerKind::Fleet, fleet),
            _ => return None,
        };
        let progress = Progress::default();
        progress.start(view.cells_total);
        progress.advance(view.cells_done.min(view.cells_total));
        let (state, _) = watch::channel(view.state);
        Some(Job {
            id: view.job_id,
            seq,
            owners: Mutex::new(owners),
            scenario_id: view.scenario_id,
            work,
            progress: Arc::new(progress),
            state,
            cancel: Notify::new(),
            times: Mutex::new(JobTimes {
                created: from_unix(view.created_at),
                started: view.started_at.and_then(from_unix),
                finished: view.finished_at.and_then(from_unix),
            }),
            error: Mutex::new(view.error),
            interrupted: Default::default(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A finished map job's record as the data directory and Redis hold it.
    const MAP_RECORD: &str = r#"{"job_id":"0123456789abcdef0123456789abcdef","seq":7,"owner":"d1gest","owners":["d1gest"],"scenario_id":"5c3na410","key":{"scenario_id":"5c3na410","kind":"gain","phases":"continuous","access":null,"solver":null},"state":"done","cells_done":40,"cells_total":40,"created_at":1700000000.25,"started_at":1700000001.5,"finished_at":1700000002.75,"error":null,"placement":null}"#;

    /// A finished placement job's record.
    const PLACEMENT_RECORD: &str = r#"{"job_id":"fedcba9876543210fedcba9876543210","seq":8,"owner":null,"owners":[],"scenario_id":"5c3na410","key":null,"state":"failed","cells_done":3,"cells_total":12,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":null,"error":"it broke","placement":[{"best":1},2]}"#;

    /// A finished Monte Carlo check's record: records carry their kind since checks exist.
    const CHECK_RECORD: &str = r#"{"job_id":"00112233445566778899aabbccddeeff","seq":9,"owner":null,"owners":[],"scenario_id":"5c3na410","kind":"check","key":null,"state":"done","cells_done":5,"cells_total":5,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":1700000009.0,"error":null,"placement":null,"check":{"feasible":true}}"#;

    /// A finished fleet plan's record.
    const FLEET_RECORD: &str = r#"{"job_id":"ffeeddccbbaa99887766554433221100","seq":10,"owner":null,"owners":[],"scenario_id":"5c3na410","kind":"fleet","key":null,"state":"done","cells_done":3,"cells_total":3,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":1700000002.0,"error":null,"placement":null,"check":null,"fleet":{"robots":[]}}"#;

    /// A record reads back as the record it was, and carries every field of today's format
    /// (so the release before this one reads it too).
    fn round_trip(record: &JobRecord, today: &str) {
        let written = serde_json::to_value(record).unwrap();
        let again: JobRecord = serde_json::from_value(written.clone()).unwrap();
        assert_eq!(serde_json::to_value(&again).unwrap(), written);
        let today: serde_json::Value = serde_json::from_str(today).unwrap();
        for (field, value) in today.as_object().unwrap() {
            assert_eq!(&written[field], value, "{field}");
        }
    }

    /// A record of the release before `owners` reads with its one owner.
    #[test]
    fn a_record_with_only_owner_reads_as_one_owner() {
        let older = MAP_RECORD.replace(r#""owners":["d1gest"],"#, "");
        let record: JobRecord = serde_json::from_str(&older).unwrap();
        assert_eq!(record.owners().digests(), ["d1gest"]);
        let job = Job::restore(record).unwrap();
        assert_eq!(job.record().owners, ["d1gest"]);
    }

    #[test]
    fn records_of_today_are_read_and_shown_as_before() {
        let map: JobRecord = serde_json::from_str(MAP_RECORD).unwrap();
        let map_id = irs_answers::map::map_id(map.view.key.as_ref().unwrap());
        let expected = format!(
            r#"{{"job_id":"0123456789abcdef0123456789abcdef","kind":"map","scenario_id":"5c3na410","map_id":"{map_id}","key":{{"scenario_id":"5c3na410","kind":"gain","phases":"continuous","access":null,"solver":null}},"state":"done","cells_done":40,"cells_total":40,"progress":1.0,"created_at":1700000000.25,"started_at":1700000001.5,"finished_at":1700000002.75,"error":null,"href":"/v1/jobs/0123456789abcdef0123456789abcdef","result_href":"/v1/maps/{map_id}"}}"#
        );
        assert_eq!(serde_json::to_string(&map.view).unwrap(), expected);
        let job = Job::restore(map).unwrap();
        assert_eq!(serde_json::to_string(&job.view()).unwrap(), expected);
        round_trip(&job.record(), MAP_RECORD);

        let placement: JobRecord = serde_json::from_str(PLACEMENT_RECORD).unwrap();
        let expected = r#"{"job_id":"fedcba9876543210fedcba9876543210","kind":"placement","scenario_id":"5c3na410","map_id":null,"key":null,"state":"failed","cells_done":3,"cells_total":12,"progress":0.25,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":null,"error":"it broke","href":"/v1/jobs/fedcba9876543210fedcba9876543210","result_href":"/v1/placements/fedcba9876543210fedcba9876543210"}"#;
        assert_eq!(serde_json::to_string(&placement.view).unwrap(), expected);
        let job = Job::restore(placement).unwrap();
        assert_eq!(serde_json::to_string(&job.view()).unwrap(), expected);
        round_trip(&job.record(), PLACEMENT_RECORD);

        let check: JobRecord = serde_json::from_str(CHECK_RECORD).unwrap();
        let expected = r#"{"job_id":"00112233445566778899aabbccddeeff","kind":"check","scenario_id":"5c3na410","map_id":null,"key":null,"state":"done","cells_done":5,"cells_total":5,"progress":1.0,"created_at":1700000000.0,"started_at":1700000001.0,"finished_at":1700000009.0,"error":null,"href":"/v1/jobs/00112233445566778899aabbccddeeff","result_href":"/v1/checks/00112233445566778899aabbccddeeff"}"#;
        assert_eq!(serde_json::to_string(&check.view).unwrap(), expected);
        let job = Job::restore(check).unwrap();
        assert_eq!(serde_json::to_string(&job.view()).unwrap(), expected);
        assert_eq!(
            job.answer(AnswerKind::Check).unwrap().answer,
            serde_json::json!({"feasible": true})
        );
        round_trip(&job.record(), CHECK_RECORD);

        let fleet: JobRecord = serde_json::from_str(FLEET_RECORD).unwrap();
        let job = Job::restore(fleet).unwrap();
        let view = serde_json::to_value(job.view()).unwrap();
        assert_eq!(view["kind"], "fleet");
        assert_eq!(
            view["result_href"],
            "/v1/fleet-plans/ffeeddccbbaa99887766554433221100"
        );
        assert_eq!(
            job.answer(AnswerKind::Fleet).unwrap().answer,
            serde_json::json!({"robots": []})
        );
        assert!(job.answer(AnswerKind::Check).is_none());
        round_trip(&job.record(), FLEET_RECORD);
    }

    /// A record whose kind and contents disagree is not restored.
    #[test]
    fn a_record_of_one_kind_with_another_kinds_answer_is_refused() {
        let odd = CHECK_RECORD.replace(r#""kind":"check""#, r#""kind":"map""#);
        assert!(Job::restore(serde_json::from_str(&odd).unwrap()).is_none());
        let odd = PLACEMENT_RECORD.replace(r#""placement":"#, r#""kind":"check","placement":"#);
        assert!(Job::restore(serde_json::from_str(&odd).unwrap()).is_none());
        let odd = FLEET_RECORD.replace(r#""kind":"fleet""#, r#""kind":"check""#);
        assert!(Job::restore(serde_json::from_str(&odd).unwrap()).is_none());
    }
}
