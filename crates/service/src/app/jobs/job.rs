//! One job: its state, its kind, what it does ([`Work`]), its times and error, how a map job
//! delivers its map to the requests waiting for it, and waiting for it to end.

use super::answers::{AnswerKind, AnswerOutcome};
use super::placements::PlacementOutcome;
use crate::app::identity::{Caller, Owner, Owners};
use crate::ids::{JobId, MapId, ScenarioId};
use irs_model::radiomap::{Checkpoint, MapKey, Progress, RadioMap};
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};
use tokio::sync::{Notify, watch};

/// Where a job is in its life; shown and recorded as its name ([`JobState::as_str`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JobState {
    Queued,
    Running,
    Done,
    Failed,
    Cancelled,
}

impl JobState {
    pub fn is_terminal(self) -> bool {
        matches!(
            self,
            JobState::Done | JobState::Failed | JobState::Cancelled
        )
    }
    const ALL: [JobState; 5] = [
        JobState::Queued,
        JobState::Running,
        JobState::Done,
        JobState::Failed,
        JobState::Cancelled,
    ];

    /// Its name: in views, records, error details and metric labels.
    pub fn as_str(self) -> &'static str {
        match self {
            JobState::Queued => "queued",
            JobState::Running => "running",
            JobState::Done => "done",
            JobState::Failed => "failed",
            JobState::Cancelled => "cancelled",
        }
    }
}

impl std::fmt::Display for JobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl Serialize for JobState {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for JobState {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        JobState::ALL
            .into_iter()
            .find(|state| state.as_str() == name)
            .ok_or_else(|| {
                serde::de::Error::invalid_value(serde::de::Unexpected::Str(&name), &"a job state")
            })
    }
}

/// What kind of job it is: shown as `kind` and labels its metrics.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JobKind {
    /// Builds a map.
    Map,
    /// Ranks placement candidates.
    Placement,
    /// Checks a path's bounds by Monte Carlo.
    Check,
    /// Plans a fleet.
    Fleet,
}

impl JobKind {
    const ALL: [JobKind; 4] = [
        JobKind::Map,
        JobKind::Placement,
        JobKind::Check,
        JobKind::Fleet,
    ];

    pub fn as_str(self) -> &'static str {
        match self {
            JobKind::Map => "map",
            JobKind::Placement => "placement",
            JobKind::Check => "check",
            JobKind::Fleet => "fleet",
        }
    }
}

impl<'de> Deserialize<'de> for JobKind {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        JobKind::ALL
            .into_iter()
            .find(|kind| kind.as_str() == name)
            .ok_or_else(|| {
                serde::de::Error::invalid_value(serde::de::Unexpected::Str(&name), &"a job kind")
            })
    }
}

impl Serialize for JobKind {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.as_str())
    }
}

/// What a job does.
pub enum Work {
    /// Builds one map (single flight by map id); `delivery` passes it to the waiters.
    Map {
        map_id: MapId,
        key: MapKey,
        delivery: Mutex<MapDelivery>,
        /// A build of this node's own, which a restart resumes if the server's shutdown
        /// interrupts it; a cluster's shared build is not (another replica takes it over).
        resumable: bool,
        /// The grid rows of a rate map it resumed from and those it solved, kept where a
        /// restart or another replica finds them (`--data-dir`, Redis).
        checkpoint: Arc<Checkpoint>,
    },
    /// Ranks placement candidates; the answer is kept here once the job is done.
    Placement {
        outcome: OnceLock<Arc<PlacementOutcome>>,
    },
    /// Computes one JSON answer (a path's Monte Carlo check, a fleet plan), kept here once done.
    Answer {
        kind: AnswerKind,
        outcome: OnceLock<Arc<AnswerOutcome>>,
    },
}

/// How a map job delivers its built map to the requests waiting for it.
#[derive(Default)]
pub struct MapDelivery {
    /// Requests waiting for the map.
    waiters: usize,
    /// The map, held while waiters remain.
    map: Option<Arc<RadioMap>>,
    /// Set when the build finished: the map for whoever comes late, while anything holds it.
    built: Option<std::sync::Weak<RadioMap>>,
}

/// One request waiting for a map job; the last to go lets the job drop the map.
struct Waiter<'a>(&'a Mutex<MapDelivery>);

impl Drop for Waiter<'_> {
    fn drop(&mut self) {
        let mut h = self.0.lock().expect("job lock");
        h.waiters -= 1;
        if h.waiters == 0 {
            h.map = None;
        }
    }
}

/// One job.
pub struct Job {
    pub id: JobId,
    /// Order of creation, for listings (newest first) and their cursors.
    pub seq: u64,
    /// The tokens that asked for it (none with authentication off): a map build shared by
    /// several tenants serves each of them, each cancel withdraws one, and the build stops only
    /// when none is left.
    pub(super) owners: Mutex<Owners>,
    /// The scenario the job works on (a live job keeps it registered).
    pub scenario_id: ScenarioId,
    pub work: Work,
    pub progress: Arc<Progress>,
    pub(super) state: watch::Sender<JobState>,
    pub(super) cancel: Notify,
    pub(super) times: Mutex<JobTimes>,
    pub(super) error: Mutex<Option<String>>,
    /// Cancelled by the server's shutdown, not by a caller.
    pub(super) interrupted: std::sync::atomic::AtomicBool,
}

#[derive(Debug, Clone, Copy, Default)]
pub(super) struct JobTimes {
    pub created: Option<SystemTime>,
    pub started: Option<SystemTime>,
    pub finished: Option<SystemTime>,
}

pub(super) fn from_unix(t: f64) -> Option<SystemTime> {
    (t.is_finite() && t >= 0.0).then(|| UNIX_EPOCH + Duration::from_secs_f64(t))
}

pub(super) fn unix(t: Option<SystemTime>) -> Option<f64> {
    t.map(|t| {
        t.duration_since(UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64())
    })
}

/// What a cancel did to a job.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Withdrawn {
    /// The caller was the last owner (or authentication is off): the job is asked to stop.
    Stopping,
    /// Other owners still want it: it goes on for them.
    SharedOn,
}

impl Job {
    /// Its owners now.
    pub fn owners(&self) -> Owners {
        self.owners.lock().expect("job lock").clone()
    }

    /// May `caller` see or cancel it? (A tenant that is not an owner is told it does not exist.)
    pub fn visible_to(&self, caller: &Caller) -> bool {
        caller.may_touch_any(&self.owners.lock().expect("job lock"))
    }

    /// Adds an owner that asked for the same work (a shared build).
    pub(super) fn join(&self, owner: Option<Owner>) {
        if let Some(owner) = owner {
            self.owners.lock().expect("job lock").insert(owner);
        }
    }

    /// Withdraws `caller`'s interest: the job stops with the last owner's. `None` when the
    /// caller is not an owner.
    pub(super) fn withdraw(&self, caller: &Caller) -> Option<Withdrawn> {
        let mut owners = self.owners.lock().expect("job lock");
        match caller {
            Caller::Open => Some(Withdrawn::Stopping),
            Caller::Anonymous => None,
            Caller::Owner(me) if !owners.contains(me) => None,
            // The last owner stays on the record: the job it stopped is still its to read.
            Caller::Owner(_) if owners.len() == 1 => Some(Withdrawn::Stopping),
            Caller::Owner(me) => {
                owners.remove(me);
                Some(Withdrawn::SharedOn)
            }
        }
    }

    pub fn state(&self) -> JobState {
        *self.state.borrow()
    }

    pub fn kind(&self) -> JobKind {
        match &self.work {
            Work::Map { .. } => JobKind::Map,
            Work::Placement { .. } => JobKind::Placement,
            Work::Answer { kind, .. } => kind.job_kind(),
        }
    }

    /// A map job's checkpoint.
    pub(super) fn checkpoint(&self) -> Option<&Arc<Checkpoint>> {
        match &self.work {
            Work::Map { checkpoint, .. } => Some(checkpoint),
            Work::Placement { .. } | Work::Answer { .. } => None,
        }
    }

    /// The map a map job builds.
    pub fn map_id(&self) -> Option<&MapId> {
        match &self.work {
            Work::Map { map_id, .. } => Some(map_id),
            Work::Placement { .. } | Work::Answer { .. } => None,
        }
    }

    /// Whether the server's shutdown interrupted it (it did not end of itself or by a
    /// caller's cancel).
    pub fn interrupted(&self) -> bool {
        self.interrupted.load(std::sync::atomic::Ordering::SeqCst)
    }

    /// A map build a restart resumes: one of this node's own, interrupted by the shutdown.
    pub(super) fn resumes(&self) -> bool {
        self.interrupted()
            && matches!(
                self.work,
                Work::Map {
                    resumable: true,
                    ..
                }
            )
    }

    /// Waits for a map job and takes its map: `None` if the build failed or was cancelled.
    pub async fn wait_for_map(&self) -> Option<Arc<RadioMap>> {
        let Work::Map { delivery, .. } = &self.work else {
            return None;
        };
        {
            let mut h = delivery.lock().expect("job lock");
            if let Some(built) = &h.built {
                return built.upgrade();
            }
            h.waiters += 1;
        }
        // Counted out on drop too: a waiter whose client left must not pin the map.
        let waiter = Waiter(delivery);
        self.finished().await;
        let map = {
            let h = delivery.lock().expect("job lock");
            h.map.clone().or_else(|| h.built.as_ref()?.upgrade())
        };
        drop(waiter);
        map
    }

    /// Hands the built map to the waiters (held only if there are some).
    pub(super) fn deliver(&self, map: &Arc<RadioMap>) {
        if let Work::Map { delivery, .. } = &self.work {
            let mut h = delivery.lock().expect("job lock");
            h.built = Some(Arc::downgrade(map));
            if h.waiters > 0 {
                h.map = Some(map.clone());
            }
        }
    }

    /// A placement job's outcome, once it is done.
    pub fn placement(&self) -> Option<Arc<PlacementOutcome>> {
        match &self.work {
            Work::Placement { outcome } => outcome.get().cloned(),
            Work::Map { .. } | Work::Answer { .. } => None,
        }
    }

    /// The answer of a job of `kind`, once it is done.
    pub fn answer(&self, kind: AnswerKind) -> Option<Arc<AnswerOutcome>> {
        match &self.work {
            Work::Answer { kind: k, outcome } if *k == kind => outcome.get().cloned(),
            Work::Answer { .. } => None,
            Work::Map { .. } | Work::Placement { .. } => None,
        }
    }

    /// The bytes its kept answer weighs in the job history (nothing for a map job).
    pub(super) fn answer_bytes(&self) -> usize {
        self.placement()
            .map(|o| o.bytes)
            .or_else(|| match &self.work {
                Work::Answer { outcome, .. } => outcome.get().map(|o| o.bytes),
                _ => None,
            })
            .unwrap_or(0)
    }

    /// Waits until the job ends.
    pub async fn finished(&self) -> JobState {
        let mut rx = self.state.subscribe();
        // The guard `wait_for` returns borrows `rx`; copy the state out before `rx` drops.
        #[allow(clippy::let_and_return)]
        let state = rx
            .wait_for(|s| s.is_terminal())
            .await
            .map(|s| *s)
            .unwrap_or(JobState::Failed);
        state
    }

    pub(super) fn set_state(&self, next: JobState) {
        let previous = self.state.send_replace(next);
        if previous != next {
            metrics::gauge!("irs_jobs", "state" => previous.as_str()).decrement(1.0);
            metrics::gauge!("irs_jobs", "state" => next.as_str()).increment(1.0);
        }
        let mut times = self.times.lock().expect("job lock");
        match next {
            JobState::Running => times.started = Some(SystemTime::now()),
            // Taken already when the record was written first (`Job::record_as`).
            s if s.is_terminal() => {
                times.finished.get_or_insert_with(SystemTime::now);
            }
            _ => {}
        }
    }
}
