//! Several IRSs and several APs on one floor (docs/model.md §2–3): the generalisations reduce to
//! the single-surface model where they must, and add up as they must.

mod common;

use common::gain_map;
use irs_answers::scenario::ScenarioDocument;
use irs_model::channel::ChannelModel;
use irs_model::phases::PhaseMode;
use irs_model::radiomap::{self, MapKey, Progress};
use irs_model::scenario::Scenario;

/// The paper floor (or `edit` of it) with its IRS whole and split into its west and east
/// halves (5 × 6 sub-surfaces each, at the very positions they had).
fn whole_and_halves(edit: impl FnOnce(&mut serde_json::Value)) -> (Scenario, Scenario) {
    let whole = Scenario::builtin_with("paper-single-user", edit)
        .unwrap()
        .unwrap();
    let irs = whole.surfaces()[0].clone();
    let pitch = irs.sub_pitch_m.unwrap();
    let half = |sign: f64| {
        let mut h = irs.clone();
        h.nx_sub = 5;
        h.center[0] += sign * 2.5 * pitch;
        h
    };
    let split = whole.with_surfaces(vec![half(-1.0), half(1.0)]).unwrap();
    (whole, split)
}

/// Splitting the IRS keeps every phase, front half-space and element: what changes is only
/// where each half's scalar path losses L_AI, L_IM and its blockage are evaluated — at its own
/// centre, 1.9 cm from the whole surface's (docs/model.md §2). On an open floor (path losses
/// only) the maps agree to 2e-3 dB (the halves' first-order changes cancel). On the paper floor
/// every cell that differs by more than that is one where a half's IRS–cell link is blocked and
/// the whole's is not, or the other way round: rays grazing an obstacle's top edge, where 1.9 cm
/// decides.
#[test]
fn splitting_an_irs_in_two_changes_only_where_its_links_are_evaluated() {
    let (whole, split) = whole_and_halves(|v| v["obstacles"] = serde_json::json!([]));
    let mut open_floor = 0.0f64;
    for phases in [PhaseMode::Continuous, PhaseMode::Bits(2)] {
        let (a, b) = (gain_map(&whole, phases), gain_map(&split, phases));
        for (x, y) in a.values.iter().zip(&b.values) {
            open_floor = open_floor.max((x - y).abs());
        }
    }
    assert!(open_floor < 2e-3, "{open_floor} dB");

    let (whole, split) = whole_and_halves(|_| {});
    let model = ChannelModel::new(&whole);
    let h = whole.mru.antenna_height_m;
    let (a, b) = (
        gain_map(&whole, PhaseMode::Continuous),
        gain_map(&split, PhaseMode::Continuous),
    );
    let centres: Vec<[f64; 3]> = split.surfaces().iter().map(|s| s.center).collect();
    let mut explained = 0;
    for (k, (x, y)) in a.values.iter().zip(&b.values).enumerate() {
        if x.is_nan() || (x - y).abs() <= open_floor {
            continue;
        }
        let (i, j) = a.grid.cell_of(k);
        let [cx, cy] = a.grid.centre(i, j);
        let blocked = |from: [f64; 3]| model.is_blocked(from, [cx, cy, h]);
        let whole_blocked = blocked(whole.surfaces()[0].center);
        assert!(
            centres.iter().any(|&c| blocked(c) != whole_blocked),
            "({cx}, {cy}) differs by {} dB with the same blockage",
            (x - y).abs()
        );
        explained += 1;
    }
    assert!(explained > 0 && explained < 40, "{explained} cells");
}

/// The paper floor with a second AP in its south-east corner (in front of the IRS).
fn two_aps() -> (Scenario, [Scenario; 2]) {
    let paper = Scenario::builtin("paper-single-user").unwrap();
    let mut second = paper.ap().clone();
    second.position = [9.5, -9.5, 2.0];
    let both = paper
        .with_access_points(vec![paper.ap().clone(), second.clone()])
        .unwrap();
    let alone = [
        paper.clone(),
        paper.with_access_points(vec![second]).unwrap(),
    ];
    (both, alone)
}

/// Each cell is served by the AP whose optimised gain is highest: the two-AP map is the
/// cell-wise maximum of the two one-AP maps, exactly, and every waypoint names the argmax.
#[test]
fn two_aps_serve_each_cell_from_the_better_one() {
    let (both, alone) = two_aps();
    for phases in [PhaseMode::Continuous, PhaseMode::Bits(1), PhaseMode::None] {
        let map = gain_map(&both, phases);
        let singles = [gain_map(&alone[0], phases), gain_map(&alone[1], phases)];
        for (k, v) in map.values.iter().enumerate() {
            let best = singles[0].values[k].max(singles[1].values[k]);
            assert!(
                v.is_nan() && best.is_nan() || *v == best,
                "{phases:?} cell {k}"
            );
        }
        let path = irs_model::planner::plan(
            &map,
            map.native_unit(),
            Default::default(),
            [-10.0, 0.0],
            [10.0, 0.0],
            irs_model::planner::Threshold::Max,
            1.0,
        )
        .unwrap();
        assert!(path.feasible);
        let mut served = [0, 0];
        for wp in &path.waypoints {
            let k = map.grid.index(wp.i, wp.j);
            let (a, b) = (singles[0].values[k], singles[1].values[k]);
            assert_eq!(
                wp.config.ap,
                usize::from(b > a),
                "{phases:?} at ({}, {})",
                wp.x,
                wp.y
            );
            assert_eq!(wp.value, a.max(b));
            served[wp.config.ap] += 1;
            // The phases are those of the serving AP's one-AP map at that cell.
            assert_eq!(wp.config, {
                let mut c = singles[wp.config.ap].cell_config(k);
                c.ap = wp.config.ap;
                c
            });
        }
        assert!(
            served[0] > 0 && served[1] > 0,
            "{phases:?}: both APs serve the path"
        );
        // Handovers are exactly the waypoints where the serving AP changes.
        let changes: Vec<(usize, usize, usize)> = path
            .waypoints
            .windows(2)
            .enumerate()
            .filter(|(_, w)| w[0].config.ap != w[1].config.ap)
            .map(|(k, w)| (k + 1, w[0].config.ap, w[1].config.ap))
            .collect();
        let listed: Vec<(usize, usize, usize)> = path
            .handovers
            .iter()
            .map(|h| (h.waypoint, h.from, h.to))
            .collect();
        assert_eq!(listed, changes);
        assert!(!listed.is_empty());
    }
}

/// A one-element `aps` is the scenario `ap` is; rate maps with several APs are refused naming
/// `aps`; an IRS with an AP behind it does nothing for that AP.
#[test]
fn ap_lists_canonicalise_and_rate_maps_take_one_ap() {
    let paper = Scenario::builtin("paper-single-user").unwrap();
    let listed = paper.with_access_points(vec![paper.ap().clone()]).unwrap();
    assert_eq!(listed.content_hash(), paper.content_hash());

    let multi = Scenario::builtin("paper-multi-user").unwrap();
    let mut second = multi.ap().clone();
    second.position = [9.5, -9.5, 2.0];
    let two = multi
        .with_access_points(vec![multi.ap().clone(), second])
        .unwrap();
    let e = MapKey::rate(
        "x",
        &two,
        PhaseMode::Continuous,
        irs_model::rate::Access::Noma,
    )
    .unwrap_err();
    assert_eq!(e.field, "aps");

    // An AP on the IRS's wall (y = −10, the surface faces +y) is behind its plane.
    let mut behind = paper.ap().clone();
    behind.position = [-8.0, -10.0, 2.0];
    let both = paper
        .with_access_points(vec![paper.ap().clone(), behind.clone()])
        .unwrap();
    let lone = both.with_access_points(vec![behind]);
    assert_eq!(
        lone.unwrap_err().field,
        "irs.normal",
        "an IRS facing no AP is refused"
    );
    let models: Vec<ChannelModel> = (0..2).map(|k| ChannelModel::for_ap(&both, k)).collect();
    let mut w = vec![irs_model::channel::C64::new(0.0, 0.0); models[1].subsurfaces()];
    let q = [-5.0, -8.5, 1.0];
    let with = models[1].evaluate(q, true, &mut w);
    assert!(w.iter().all(|x| x.norm() == 0.0));
    assert_eq!(with, models[1].evaluate(q, false, &mut w));
    // The AP in front of it still gets the surface.
    let mut w0 = vec![irs_model::channel::C64::new(0.0, 0.0); models[0].subsurfaces()];
    models[0].evaluate(q, true, &mut w0);
    assert!(w0.iter().all(|x| x.norm() > 0.0));
}

/// Rate maps take the concatenated vector too: with a second surface on the small floor, every
/// cell's rate stays within its certificate and waypoints carry one phase vector per surface.
#[test]
fn rate_maps_solve_and_certify_the_concatenated_vector() {
    let small = Scenario::builtin("small-test").unwrap();
    let first = small.surfaces()[0].clone();
    let mut second = first.clone();
    (second.center, second.normal, second.nx_sub, second.nz_sub) =
        ([6.0, 2.0, 1.8], [-1.0, 0.0, 0.0], 3, 1);
    let two = small.with_surfaces(vec![first, second]).unwrap();
    let key = MapKey::rate(
        &two.content_hash(),
        &two,
        PhaseMode::Continuous,
        irs_model::rate::Access::Noma,
    )
    .unwrap();
    let map = irs_answers::map::build(&two, &key, &Progress::default()).unwrap();
    let radiomap::CellSolutions::Rate(cells) = &map.cells else {
        panic!("a rate map")
    };
    let mut solved = 0;
    for (k, v) in map.values.iter().enumerate() {
        if v.is_finite() {
            assert!(
                *v <= cells.upper_bound[k] + 1e-9,
                "cell {k}: {v} above {}",
                cells.upper_bound[k]
            );
            let phases = map.cell_config(k).phases;
            assert_eq!(phases.iter().map(Vec::len).collect::<Vec<_>>(), [4, 3]);
            solved += 1;
        }
    }
    assert!(solved > 50, "{solved} cells solved");
}
