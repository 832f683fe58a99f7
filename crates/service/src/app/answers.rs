//! Path answers kept by query, so that the routes a fleet asks for again and again (a shuttle
//! between two stations, a patrol loop) are answered by a lookup and a copy instead of a search,
//! the phases of every waypoint and the JSON of a few thousand numbers.
//!
//! A path answer is a pure function of its map and its query, and a map id is a hash of
//! everything the map was built from, so a kept answer can never go stale. It is looked up
//! only after the map itself has been found (and the caller's access to it checked): a deleted
//! map answers 404 however many of its answers are still kept. Answers with a Monte Carlo
//! check are not kept (they are rare, go through admission control, and are cheap to repeat
//! next to their draws).
//!
//! An answer is kept as its JSON without the closing brace; `took_ms` (the time this request
//! took, a lookup for a kept answer) is appended per request.

use crate::app::Error;
use crate::ids::MapId;
use bytes::Bytes;
use irs_answers::path::FrameId;
use irs_answers::phase_text::{PhaseFormat, PhasePrecision};
use irs_model::planner::{PathOptions, PathShape, Threshold};
use irs_model::radiomap::Unit;

/// What a path answer depends on besides its map's content: the map's id and the query's
/// fields, the coordinates as their exact bits (an answer repeats the requested points).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(crate) struct PathQuery {
    map_id: MapId,
    start: [u64; 2],
    goal: [u64; 2],
    /// `None` for `"max"`.
    threshold: Option<u64>,
    unit: Unit,
    shape: PathShape,
    tolerance: u64,
    format: PhaseFormat,
    precision: PhasePrecision,
    frame: FrameId,
}

impl PathQuery {
    pub fn new(
        map_id: MapId,
        start: [f64; 2],
        goal: [f64; 2],
        (threshold, unit, options): (Threshold, Unit, PathOptions),
        (format, precision): (PhaseFormat, PhasePrecision),
        frame: FrameId,
    ) -> Self {
        PathQuery {
            map_id,
            start: start.map(f64::to_bits),
            goal: goal.map(f64::to_bits),
            threshold: match threshold {
                Threshold::Value(v) => Some(v.to_bits()),
                Threshold::Max => None,
            },
            unit,
            shape: options.shape,
            tolerance: options.tolerance_m.to_bits(),
            format,
            precision,
            frame,
        }
    }

    /// Bytes the key holds, for the weigher.
    fn bytes(&self) -> usize {
        std::mem::size_of::<Self>() + self.map_id.as_str().len() + self.frame.as_str().len()
    }
}

/// A JSON object's text without its closing brace, to which `took_ms` is appended per request.
#[derive(Debug, Clone)]
pub(crate) struct OpenAnswer(Bytes);

impl OpenAnswer {
    /// `body`, a serialised JSON object, opened for its last field.
    pub fn new(mut body: Vec<u8>) -> Result<Self, Error> {
        match body.pop() {
            Some(b'}') => Ok(OpenAnswer(Bytes::from(body))),
            _ => Err(Error::internal("a path answer is a JSON object")),
        }
    }

    /// The answer's text without its closing brace (shared, not copied): `took_ms` is
    /// written after it, when the answer is sent (where [`irs_answers::timing::Timed`] writes
    /// it).
    pub fn open_text(&self) -> Bytes {
        self.0.clone()
    }
}

/// The kept answers, least recently used evicted first, weighed in bytes.
pub(crate) struct AnswerCache {
    answers: moka::sync::Cache<PathQuery, OpenAnswer>,
}

impl AnswerCache {
    /// A cache of `budget_bytes`; 0 keeps nothing.
    pub fn new(budget_bytes: u64) -> Self {
        let answers = moka::sync::Cache::builder()
            .eviction_policy(moka::policy::EvictionPolicy::lru())
            .max_capacity(budget_bytes)
            .weigher(|query: &PathQuery, answer: &OpenAnswer| {
                (query.bytes() + answer.0.len()).min(u32::MAX as usize) as u32
            })
            .build();
        AnswerCache { answers }
    }

    pub fn get(&self, query: &PathQuery) -> Option<OpenAnswer> {
        let found = self.answers.get(query);
        let outcome = if found.is_some() { "hit" } else { "miss" };
        metrics::counter!("irs_answer_cache_requests_total", "outcome" => outcome).increment(1);
        found
    }

    pub fn insert(&self, query: PathQuery, answer: OpenAnswer) {
        self.answers.insert(query, answer);
    }
}
