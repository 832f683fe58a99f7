//! Placement search (docs/model.md §7): the ranking equals an exhaustive loop that builds every
//! candidate's map with the ordinary map builder and scores it with the ordinary planner.

mod common;

use common::{Q_F, Q_I};
use irs_answers::scenario::ScenarioDocument;

use irs_model::phases::PhaseMode;
use irs_model::placement::{self, Candidates, Objective, Search, Segment, What};
use irs_model::planner::{self, Threshold};
use irs_model::radiomap::{MapKey, Progress};
use irs_model::scenario::Scenario;

fn walls(segments: &[([f64; 2], [f64; 2])], step: f64) -> Candidates {
    Candidates {
        poses: Vec::new(),
        positions: Vec::new(),
        walls: segments
            .iter()
            .map(|&(from, to)| Segment { from, to })
            .collect(),
        step_m: Some(step),
        height_m: None,
    }
}

/// The score of one candidate scenario, the slow way: a fresh document through the ordinary
/// parser, the ordinary builder, the ordinary planner.
fn exhaustive_score(s: &Scenario, objective: &Objective, phases: PhaseMode) -> Option<f64> {
    let fresh = Scenario::from_json(&s.canonical_json()).unwrap();
    let key = MapKey::gain(&fresh.content_hash(), &fresh, phases).unwrap();
    let map = irs_answers::map::build(&fresh, &key, &Progress::default()).unwrap();
    match *objective {
        Objective::Coverage { threshold } => Some(map.coverage(threshold)),
        Objective::MaxThreshold { start, goal } => {
            planner::plan(
                &map,
                map.native_unit(),
                Default::default(),
                start,
                goal,
                Threshold::Max,
                1.0,
            )
            .unwrap()
            .max_feasible_threshold
        }
        Objective::Distance {
            threshold,
            start,
            goal,
        } => {
            planner::plan(
                &map,
                map.native_unit(),
                Default::default(),
                start,
                goal,
                Threshold::Value(threshold),
                1.0,
            )
            .unwrap()
            .distance_m
        }
    }
}

fn check_against_exhaustive(base: &Scenario, search: &Search) -> placement::PlacementAnswer {
    let found = placement::place(
        base,
        search,
        &irs_answers::map::ContentIds,
        &Progress::default(),
    )
    .unwrap();
    let answer = found.answer;
    let phases = search.phases.unwrap_or(PhaseMode::Continuous);
    let lower_is_better = matches!(search.objective, Objective::Distance { .. });
    let mut previous: Option<Option<f64>> = None;
    for (ranked, scenario) in answer.candidates.iter().zip(&found.scenarios) {
        let slow = exhaustive_score(scenario, &search.objective, phases);
        match (ranked.score, slow) {
            (Some(a), Some(b)) => assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{a} vs {b}"),
            (a, b) => assert_eq!(a, b),
        }
        assert_eq!(ranked.scenario_id, scenario.content_hash());
        // Best first: each exhaustive score is no better than the one before (to 1e-9).
        if let Some(prev) = previous {
            match (prev, slow) {
                (Some(p), Some(s)) if lower_is_better => assert!(s >= p - 1e-9),
                (Some(p), Some(s)) => assert!(s <= p + 1e-9, "{s} ranked after {p}"),
                (None, Some(_)) => panic!("a feasible candidate ranked after an infeasible one"),
                _ => {}
            }
        }
        previous = Some(slow);
    }
    answer
}

/// Every 0.5 m of the paper floor's four walls, for the largest threshold q_I → q_F: the north
/// wall's candidates are rejected (the AP hangs there, on their plane), the rest ranked as the
/// exhaustive loop ranks them. The paper's centre of the y = −10 wall is among the best.
#[test]
fn the_paper_floor_ranking_equals_the_exhaustive_loop() {
    let base = Scenario::builtin("paper-single-user").unwrap();
    let (a, b, c, d) = ([-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]);
    let search = Search {
        what: What::Irs,
        index: 0,
        candidates: walls(&[(a, b), (b, c), (c, d), (d, a)], 0.5),
        objective: Objective::MaxThreshold {
            start: Q_I,
            goal: Q_F,
        },
        phases: None,
    };
    let answer = check_against_exhaustive(&base, &search);
    assert_eq!(answer.candidates.len() + answer.rejected.len(), 164);
    assert!(
        answer.rejected.iter().all(|r| r.center[1] == 10.0),
        "{:?}",
        answer.rejected
    );
    let best = &answer.candidates[0];
    println!(
        "best: {:?} facing {:?}: {:?} dB",
        best.center, best.normal, best.score
    );
    let south: Vec<_> = answer
        .candidates
        .iter()
        .filter(|c| c.center[1] == -10.0)
        .collect();
    let paper = south.iter().find(|c| c.center[0] == 0.0).unwrap();
    println!(
        "paper's centre: rank {} of {}, {:?} dB",
        paper.rank,
        answer.candidates.len(),
        paper.score
    );
    for c in south.iter().take(5) {
        println!(
            "  south wall rank {}: x = {}, {:?} dB",
            c.rank, c.center[0], c.score
        );
    }
}

/// Coverage and distance objectives, 2-bit phases, and the AP moving instead of the IRS.
#[test]
fn every_objective_and_the_ap_rank_as_the_exhaustive_loop() {
    let base = Scenario::builtin("paper-single-user").unwrap();
    let south = walls(&[([-10.0, -10.0], [10.0, -10.0])], 1.0);
    for (objective, phases) in [
        (Objective::Coverage { threshold: -62.0 }, None),
        (
            Objective::Distance {
                threshold: -61.0,
                start: Q_I,
                goal: Q_F,
            },
            Some(PhaseMode::Bits(2)),
        ),
    ] {
        let search = Search {
            what: What::Irs,
            index: 0,
            candidates: south.clone(),
            objective,
            phases,
        };
        check_against_exhaustive(&base, &search);
    }
    let north = walls(&[([-10.0, 10.0], [10.0, 10.0])], 2.0);
    let search = Search {
        what: What::Ap,
        index: 0,
        candidates: north,
        objective: Objective::MaxThreshold {
            start: Q_I,
            goal: Q_F,
        },
        phases: None,
    };
    let answer = check_against_exhaustive(&base, &search);
    assert_eq!(answer.candidates.len(), 11);
}

/// Two APs and two IRSs, the second moving: a candidate's map is the shared part (both direct
/// links and the first surface, per AP) plus the moving surface's own terms, best over the APs;
/// continuous phases take the row form, 1-bit phases and `elements` grouping the cell form.
#[test]
fn several_aps_and_surfaces_rank_as_the_exhaustive_loop() {
    for (phases, grouping) in [
        (None, "coherent"),
        (Some(PhaseMode::Bits(1)), "coherent"),
        (None, "elements"),
    ] {
        let base = Scenario::builtin_with("paper-single-user", |v| {
            v["grid"]["resolution_m"] = 1.0.into();
            let ap = v["ap"].take();
            let mut second = ap.clone();
            second["position"] = serde_json::json!([-10.0, 3.0, 2.0]);
            second["tx_power_dbm"] = 17.0.into();
            v.as_object_mut().unwrap().remove("ap");
            v["aps"] = serde_json::json!([ap, second]);
            let irs = v["irs"].take();
            let mut other = irs.clone();
            other["center"] = serde_json::json!([10.0, 2.0, 2.0]);
            other["normal"] = serde_json::json!([-1.0, 0.0, 0.0]);
            v.as_object_mut().unwrap().remove("irs");
            let (mut first, mut moving) = (irs, other);
            for s in [&mut first, &mut moving] {
                s["grouping"] = grouping.into();
                if grouping == "elements" {
                    s["nx_sub"] = 4.into();
                    s["nz_sub"] = 2.into();
                    s["elements_per_sub"] = 2.into();
                }
            }
            v["irss"] = serde_json::json!([first, moving]);
        })
        .unwrap()
        .unwrap();
        // The second surface moves along the east wall, then the first along the south wall
        // (the other surface staying put in the shared part either way).
        for (index, wall) in [
            (1, ([10.0, -10.0], [10.0, 10.0])),
            (0, ([-10.0, -10.0], [10.0, -10.0])),
        ] {
            let search = Search {
                what: What::Irs,
                index,
                candidates: walls(&[wall], 2.0),
                objective: Objective::MaxThreshold {
                    start: Q_I,
                    goal: Q_F,
                },
                phases,
            };
            let answer = check_against_exhaustive(&base, &search);
            assert!(
                answer.candidates.len() >= 8,
                "{grouping} {phases:?} {index}: {} ranked",
                answer.candidates.len()
            );
        }
    }
}

/// A floor plan (the warehouse's 5 cm raster at 1 m cells): every candidate's links walk the
/// raster, as the map builder's do.
#[test]
fn a_floor_plan_ranks_as_the_exhaustive_loop() {
    let base = Scenario::from_file(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/scenarios/warehouse/warehouse.json"
    )))
    .unwrap();
    let base = {
        let mut v = base.to_json_value();
        v["grid"]["resolution_m"] = 1.0.into();
        Scenario::from_value(v).unwrap()
    };
    let search = Search {
        what: What::Irs,
        index: 0,
        candidates: walls(&[([30.0, -20.0], [30.0, 20.0])], 4.0),
        objective: Objective::MaxThreshold {
            start: [-27.0, 16.0],
            goal: [26.0, -16.0],
        },
        phases: None,
    };
    let answer = check_against_exhaustive(&base, &search);
    assert!(answer.candidates.len() >= 8);
}
