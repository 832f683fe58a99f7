//! Fuzzes what an anonymous client controls most: a scenario document. Any bytes go through
//! parsing and validation; a document that passes and is cheap to build (by the service's own
//! cost estimate) is built as gain maps in two phase modes and planned across, so the
//! validation is tested against what the engine then does with the document. A panic, an
//! overflow (checked in this build) or a NaN where the map promises a number is a finding.

#![no_main]

use irs_answers::scenario::ScenarioDocument;
use irs_model::phases::PhaseMode;
use irs_model::planner::{self, PathOptions, PathShape, Threshold};
use irs_model::radiomap::{MapKey, MapKind, Progress, cost};
use irs_model::scenario::Scenario;
use libfuzzer_sys::fuzz_target;

/// Largest estimated build (seconds of one core) the target runs, so each input stays fast.
const MAX_BUILD_S: f64 = 0.002;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let Ok(scenario) = Scenario::from_json(text) else {
        return;
    };
    // Validation is idempotent: the canonical form parses to the same scenario.
    let again = Scenario::from_json(&scenario.canonical_json()).expect("canonical form parses");
    assert_eq!(again.content_hash(), scenario.content_hash());
    let modes = [PhaseMode::Continuous, PhaseMode::Bits(2)];
    for mode in modes {
        let phases = (!scenario.surfaces().is_empty()).then_some(mode);
        let Ok(key) = MapKey::new("fuzz", &scenario, MapKind::Gain, phases, None, None) else {
            continue;
        };
        if cost::build_seconds(&scenario, &key) > MAX_BUILD_S {
            return;
        }
        let map =
            irs_answers::map::build(&scenario, &key, &Progress::default()).expect("not cancelled");
        for (value, occupied) in map.values.iter().zip(&map.occupied) {
            assert!(*occupied || !value.is_nan(), "a free cell without a value");
        }
        let grid = &map.grid;
        let first = grid.centre(0, 0);
        let last = grid.centre(grid.nx - 1, grid.ny - 1);
        let mut lengths = Vec::new();
        for shape in [PathShape::Grid, PathShape::AnyAngle] {
            let options = PathOptions {
                shape,
                ..PathOptions::default()
            };
            let v_max = scenario.mru.v_max_mps;
            let unit = map.native_unit();
            if let Ok(path) = planner::plan(&map, unit, options, first, last, Threshold::Max, v_max) {
                if let Some(t) = path.threshold {
                    for waypoint in &path.waypoints {
                        assert!(waypoint.value >= t, "a waypoint below the path's threshold");
                    }
                }
                lengths.push(path.distance_m);
            }
        }
        if let [Some(grid), Some(any)] = lengths[..] {
            assert!(any <= grid + 1e-9, "an any-angle path longer than the grid path");
        }
    }
});
