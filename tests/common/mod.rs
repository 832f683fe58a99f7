//! Helpers shared by the integration tests: the paper's end points and maps built the ordinary
//! way (key from the scenario's id, default progress).
//!
//! Each test file is its own crate and uses only some of these, hence `dead_code` allowed.
#![allow(dead_code)]

use irs_answers::scenario::ScenarioDocument;
use irs_model::phases::PhaseMode;
use irs_model::radiomap::{MapKey, MapKind, Progress, RadioMap};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;

/// The paper's start q_I and goal q_F (Section IV).
pub const Q_I: [f64; 2] = [-10.0, 0.0];
pub const Q_F: [f64; 2] = [10.0, 0.0];

/// A gain map of `s`, built as the service builds it.
pub fn gain_map(s: &Scenario, phases: PhaseMode) -> RadioMap {
    build(s, MapKind::Gain, phases, None)
}

/// A map of `s` of any kind, built as the service builds it (`access` for rate maps).
pub fn build(s: &Scenario, kind: MapKind, phases: PhaseMode, access: Option<Access>) -> RadioMap {
    let key = MapKey::new(&s.content_hash(), s, kind, Some(phases), access, None).unwrap();
    irs_answers::map::build(s, &key, &Progress::default()).unwrap()
}
