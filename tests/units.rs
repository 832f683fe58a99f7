//! Thresholds and values in the units of the link budget (docs/model.md §3.1), checked against
//! independent oracles: one-AP maps combined by hand, the rate maps' own solver, brute force over
//! the cells a path visits.

// Cells are compared across several maps and units by flat index.
#![allow(clippy::needless_range_loop)]

mod common;

use common::build;
use irs_answers::encoding;
use irs_answers::scenario::ScenarioDocument;
use irs_model::phases::PhaseMode;
use irs_model::planner::{self, Threshold, UnitIndex};
use irs_model::radiomap::{MapKind, RadioMap, Unit};
use irs_model::rate::Access;
use irs_model::scenario::Scenario;

fn paper() -> Scenario {
    Scenario::builtin("paper-single-user").unwrap()
}

/// The paper floor with two APs of different powers, antennas and bandwidths, a robot antenna
/// and a fade margin.
fn two_unequal_aps() -> Scenario {
    let s = paper();
    let mut first = s.ap().clone();
    first.antenna_gain_dbi = 2.0;
    first.bandwidth_mhz = Some(20.0);
    let mut second = s.ap().clone();
    second.position = [9.5, -9.5, 2.0];
    second.tx_power_dbm = 30.0;
    second.noise_dbm = -88.0;
    second.bandwidth_mhz = Some(40.0);
    let mut value = s
        .with_access_points(vec![first, second])
        .unwrap()
        .to_json_value();
    value["channel"]["rx_antenna_gain_dbi"] = 1.5.into();
    value["channel"]["fade_margin_db"] = 4.0.into();
    Scenario::from_value(value).unwrap()
}

fn dbm_to_mw(dbm: f64) -> f64 {
    10f64.powf(dbm / 10.0)
}

/// With APs of different budgets, the serving AP is the one received strongest and the map's
/// value stays the best gain: both checked cell by cell against the one-AP maps, and every
/// unit against the formulas of §3.1 applied to those maps by hand.
#[test]
fn several_aps_serve_by_received_power_and_convert_per_cell() {
    let s = two_unequal_aps();
    let map = build(&s, MapKind::Gain, PhaseMode::Continuous, None);
    let alone: Vec<RadioMap> = (0..2)
        .map(|k| {
            let one = s
                .with_access_points(vec![s.access_points()[k].clone()])
                .unwrap();
            build(&one, MapKind::Gain, PhaseMode::Continuous, None)
        })
        .collect();
    let offsets = [20.0 + 2.0 + 1.5 - 4.0, 30.0 + 1.5 - 4.0];
    let noise = [-90.0, -88.0];
    let bandwidth = [20.0, 40.0];
    let units: Vec<Vec<f64>> = Unit::ALL
        .iter()
        .map(|&u| map.values_in(u).unwrap().into_owned())
        .collect();
    let mut served_by_weaker_gain = 0;
    for c in 0..map.values.len() {
        let g = [alone[0].values[c], alone[1].values[c]];
        if map.occupied[c] {
            assert!(map.values[c].is_nan());
            continue;
        }
        assert!((map.values[c] - g[0].max(g[1])).abs() < 1e-9, "cell {c}");
        let received = [g[0] + offsets[0], g[1] + offsets[1]];
        let ap = usize::from(received[1] > received[0]);
        assert_eq!(map.cell_config(c).ap, ap, "cell {c}");
        served_by_weaker_gain += usize::from(g[ap] < g[1 - ap]);
        let snr = received[ap] - noise[ap];
        let se = (1.0 + 10f64.powf(snr / 10.0)).log2();
        let expected = [map.values[c], received[ap], snr, se, bandwidth[ap] * se];
        for (u, want) in expected.iter().enumerate() {
            let got = units[u][c];
            assert!(
                (got - want).abs() <= 1e-9 * want.abs().max(1.0),
                "{:?} at cell {c}: {got} vs {want}",
                Unit::ALL[u]
            );
        }
    }
    // The 10 dB stronger AP serves cells where the other has the better channel.
    assert!(served_by_weaker_gain > 20, "{served_by_weaker_gain} cells");
    // What a stored map keeps gives the same values in every unit.
    let back = encoding::decode(&encoding::encode(&map), &s).unwrap();
    for u in Unit::ALL {
        let (a, b) = (map.values_in(u).unwrap(), back.values_in(u).unwrap());
        assert!(
            a.iter()
                .zip(b.iter())
                .all(|(x, y)| x.to_bits() == y.to_bits())
        );
    }
}

/// One AP: a path in dBm is the path at the gain threshold shifted by the budget, its widest
/// threshold shifted alike, and every waypoint's value is its received power.
#[test]
fn a_dbm_threshold_is_a_shifted_gain_threshold_with_one_ap() {
    let s = paper();
    let map = build(&s, MapKind::Gain, PhaseMode::Continuous, None);
    let offset = s.ap().tx_power_dbm;
    let (start, goal) = ([-10.0, 0.0], [10.0, 0.0]);
    for gamma_db in [-63.0, -61.0, -60.0] {
        let in_db = planner::plan(
            &map,
            Unit::GainDb,
            Default::default(),
            start,
            goal,
            Threshold::Value(gamma_db),
            1.0,
        )
        .unwrap();
        let index = UnitIndex::new(&map, Unit::Dbm).unwrap();
        let in_dbm = planner::plan_indexed(
            &map,
            &index,
            Default::default(),
            start,
            goal,
            Threshold::Value(gamma_db + offset),
            1.0,
        )
        .unwrap();
        assert_eq!(in_dbm.unit, Unit::Dbm);
        assert_eq!(in_db.feasible, in_dbm.feasible, "γ = {gamma_db} dB");
        let cells =
            |p: &planner::PathAnswer| p.waypoints.iter().map(|w| (w.i, w.j)).collect::<Vec<_>>();
        assert_eq!(cells(&in_db), cells(&in_dbm));
        for (a, b) in in_db.waypoints.iter().zip(&in_dbm.waypoints) {
            assert!((b.value - (a.value + offset)).abs() < 1e-9);
            assert!(b.value >= gamma_db + offset);
        }
        let widest = (
            in_db.max_feasible_threshold.unwrap(),
            in_dbm.max_feasible_threshold.unwrap(),
        );
        assert!((widest.1 - (widest.0 + offset)).abs() < 1e-9, "{widest:?}");
    }
}

/// A path in Mbit/s with two APs of different budgets never enters a cell below the
/// threshold, and its widest threshold is the brute-force widest path over the converted map.
#[test]
fn a_throughput_path_with_two_aps_meets_its_threshold_everywhere() {
    let s = two_unequal_aps();
    let map = build(&s, MapKind::Gain, PhaseMode::Continuous, None);
    let index = UnitIndex::new(&map, Unit::Mbps).unwrap();
    let mbps = map.values_in(Unit::Mbps).unwrap();
    let (start, goal) = ([-9.0, 8.0], [8.0, -8.0]);
    let widest = planner::plan(
        &map,
        Unit::Mbps,
        Default::default(),
        start,
        goal,
        Threshold::Max,
        1.0,
    )
    .unwrap()
    .max_feasible_threshold
    .unwrap();
    let graph = planner::CellGraph {
        grid: &map.grid,
        values: &mbps,
        occupied: &map.occupied,
    };
    let (s_cell, g_cell) = (
        map.grid.index(
            map.grid.snap(start[0], start[1]).unwrap().0,
            map.grid.snap(start[0], start[1]).unwrap().1,
        ),
        map.grid.index(
            map.grid.snap(goal[0], goal[1]).unwrap().0,
            map.grid.snap(goal[0], goal[1]).unwrap().1,
        ),
    );
    assert_eq!(graph.widest_path_threshold(s_cell, g_cell), Some(widest));
    for gamma in [widest * 0.5, widest * 0.9, widest] {
        let path = planner::plan_indexed(
            &map,
            &index,
            Default::default(),
            start,
            goal,
            Threshold::Value(gamma),
            1.0,
        )
        .unwrap();
        assert!(path.feasible, "γ = {gamma}");
        for w in &path.waypoints {
            assert!(w.value >= gamma);
            assert_eq!(w.value, mbps[map.grid.index(w.i, w.j)]);
        }
        assert_eq!(path.unit.symbol(), "Mbit/s");
    }
    let above = planner::plan_indexed(
        &map,
        &index,
        Default::default(),
        start,
        goal,
        Threshold::Value(widest * 1.001),
        1.0,
    )
    .unwrap();
    assert!(!above.feasible);
}

/// For one user, a rate map's rate is log₂(1 + P·λ*/σ²) at the best gain λ*: the NOMA rate
/// map (the solver) with a static robot that needs no rate (so it gets no power and the MRU
/// all of it) and the gain map read in bit/s/Hz (the closed form and the link budget) agree,
/// antenna gains and fade margin included, and Mbit/s is B times either.
#[test]
fn one_users_rate_map_agrees_with_the_gain_map_in_bit_per_hz() {
    let mut value = Scenario::builtin("small-test").unwrap().to_json_value();
    value["srus"][0]["min_rate_bps_hz"] = 0.0.into();
    value["ap"]["antenna_gain_dbi"] = 3.0.into();
    value["ap"]["bandwidth_mhz"] = 20.0.into();
    value["channel"]["rx_antenna_gain_dbi"] = 2.0.into();
    value["channel"]["fade_margin_db"] = 6.0.into();
    let s = Scenario::from_value(value).unwrap();
    let gain = build(&s, MapKind::Gain, PhaseMode::Continuous, None);
    let rate = build(&s, MapKind::Rate, PhaseMode::Continuous, Some(Access::Noma));
    let from_gain = gain.values_in(Unit::BpsHz).unwrap();
    let mut compared = 0;
    for c in 0..gain.values.len() {
        if gain.occupied[c] || rate.values[c].is_nan() {
            continue;
        }
        let (a, b) = (from_gain[c], rate.values[c]);
        assert!((a - b).abs() <= 1e-3 * a.max(1.0), "cell {c}: {a} vs {b}");
        compared += 1;
    }
    assert!(compared > 50, "{compared} cells");
    let mbps = rate.values_in(Unit::Mbps).unwrap();
    assert!(
        rate.values
            .iter()
            .zip(mbps.iter())
            .all(|(r, m)| r.is_nan() && m.is_nan() || (m - 20.0 * r).abs() < 1e-12)
    );
    // The same received power a second way: the budget's terms by hand.
    let dbm = gain.values_in(Unit::Dbm).unwrap();
    let c = (0..gain.values.len()).find(|&c| !gain.occupied[c]).unwrap();
    assert!((dbm[c] - (gain.values[c] + 20.0 + 3.0 + 2.0 - 6.0)).abs() < 1e-12);
    assert!(dbm_to_mw(dbm[c]) > 0.0);
}

/// Units a map cannot answer are refused naming `unit` and what is missing.
#[test]
fn units_a_map_cannot_answer_are_refused_with_the_reason() {
    let s = Scenario::builtin("small-test").unwrap();
    let rate = build(&s, MapKind::Rate, PhaseMode::Continuous, Some(Access::Noma));
    for unit in [Unit::GainDb, Unit::Dbm, Unit::SnrDb] {
        let e = rate.values_in(unit).unwrap_err();
        assert_eq!(e.field, "unit");
        assert!(e.reason.contains("bps_hz or mbps"), "{}", e.reason);
    }
    let e = rate.values_in(Unit::Mbps).unwrap_err();
    assert!(e.reason.contains("ap.bandwidth_mhz"), "{}", e.reason);
    let gain = build(&s, MapKind::Gain, PhaseMode::Continuous, None);
    assert!(
        gain.values_in(Unit::Mbps)
            .unwrap_err()
            .reason
            .contains("ap.bandwidth_mhz")
    );
    let e = planner::plan(
        &gain,
        Unit::Mbps,
        Default::default(),
        [0.5, 0.5],
        [5.5, 3.5],
        Threshold::Max,
        1.0,
    )
    .unwrap_err();
    assert_eq!(e.field, "unit");
    // Scenario fields out of range are refused naming them.
    let mut value = s.to_json_value();
    value["ap"]["bandwidth_mhz"] = 0.0.into();
    let e = Scenario::from_value(value).unwrap_err();
    assert_eq!(e.field, "ap.bandwidth_mhz");
    let mut value = s.to_json_value();
    value["channel"]["fade_margin_db"] = (-1.0).into();
    assert_eq!(
        Scenario::from_value(value).unwrap_err().field,
        "channel.fade_margin_db"
    );
    let mut value = s.to_json_value();
    value["channel"]["rx_antenna_gain_dbi"] = 80.0.into();
    assert_eq!(
        Scenario::from_value(value).unwrap_err().field,
        "channel.rx_antenna_gain_dbi"
    );
    // At their defaults the new fields stay out of the document, so ids are unchanged.
    let text = s.canonical_json();
    for field in ["antenna_gain_dbi", "bandwidth_mhz", "fade_margin_db"] {
        // (rx_antenna_gain_dbi contains antenna_gain_dbi: one check covers both.)
        assert!(!text.contains(field), "{field} in {text}");
    }
}

/// The Monte Carlo check compares each waypoint with the gain its serving AP gives: on a floor
/// where the stronger transmitter serves cells with the weaker channel, the sampled mean matches
/// that gain (within sampling noise), not the best AP's.
#[test]
fn the_monte_carlo_check_uses_the_serving_aps_gain() {
    let s = two_unequal_aps();
    let map = build(&s, MapKind::Gain, PhaseMode::Continuous, None);
    let path = planner::plan(
        &map,
        Unit::GainDb,
        Default::default(),
        [-9.0, 8.0],
        [8.0, -8.0],
        Threshold::Max,
        1.0,
    )
    .unwrap();
    assert!(path.feasible);
    let report = irs_model::montecarlo::check_path(
        &s,
        &map,
        &path,
        4000,
        7,
        &irs_model::radiomap::Progress::default(),
    )
    .unwrap();
    let mut weaker = 0;
    for (w, check) in path.waypoints.iter().zip(&report.waypoints) {
        let user = &check.users[0];
        assert!(
            user.gap.abs() <= 5.0 * user.std_error + 0.05,
            "cell ({}, {}): bound {} vs mean {}",
            w.i,
            w.j,
            user.bound,
            user.monte_carlo_mean
        );
        weaker += usize::from(user.bound < w.value - 1e-9);
    }
    assert!(
        weaker > 0,
        "the path never met a cell served by the weaker channel"
    );
}
