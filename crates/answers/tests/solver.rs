//! Rate-map solver checks: the `fast` solver against random phases and the certificate, the
//! Monte Carlo check against the Jensen bound, and (feature `sdp`) the certificate and `fast`
//! against Clarabel's SDR and the paper's SDR+SCA.

use irs_answers::scenario::ScenarioDocument;
use irs_model::channel::{C64, ChannelModel};
use irs_model::montecarlo;
use irs_model::phases::PhaseMode;
use irs_model::planner::{self, Threshold};
use irs_model::radiomap::{MapKey, MapKind, Progress};
use irs_model::rate::{Access, RateModel};
use irs_model::scenario::Scenario;
use irs_model::solver::SolverKind;
use irs_model::solver::{self, CellProblem, certificate, fast, objective};
use rand::{RngExt, SeedableRng};
use std::f64::consts::TAU;

fn small(edit: impl FnOnce(&mut serde_json::Value)) -> Scenario {
    Scenario::builtin_with("small-test", edit).unwrap().unwrap()
}

fn problems(
    s: &Scenario,
    access: Access,
    cells: usize,
    seed: u64,
) -> Vec<(CellProblem, RateModel)> {
    let model = RateModel::for_scenario(s, access);
    let channel = ChannelModel::new(s);
    let srus = solver::sru_part(&channel, s, true);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..cells)
        .map(|_| {
            let q = [
                rng.random_range(0.2..5.8),
                rng.random_range(0.3..3.8),
                s.mru.antenna_height_m,
            ];
            (
                solver::cell_problem(&channel, q, &srus, true),
                model.clone(),
            )
        })
        .collect()
}

fn rate_of(problem: &CellProblem, model: &RateModel, v: &[C64]) -> f64 {
    let mut lambdas = vec![0.0; problem.users()];
    problem.lambdas(v, &mut lambdas);
    objective(model, &lambdas)
}

/// `fast` beats the best of 3000 random phase vectors; the certificate bounds both.
#[test]
fn fast_beats_random_phases_and_the_certificate_bounds_everything() {
    for (k, access) in [Access::Noma, Access::Oma].into_iter().enumerate() {
        let s = small(|v| {
            v["irs"]["nx_sub"] = 3.into();
            v["irs"]["nz_sub"] = 2.into();
        });
        let mut rng = rand::rngs::StdRng::seed_from_u64(99);
        for (problem, model) in problems(&s, access, 12, k as u64) {
            let v = fast::solve(&problem, &model);
            let achieved = rate_of(&problem, &model, &v);
            let bound = certificate::certify(&problem, &model, Some(&v)).upper_bound;
            assert!(
                bound >= achieved - 1e-9,
                "{access:?}: bound {bound} < fast {achieved}"
            );
            let mut best_random = f64::NEG_INFINITY;
            for _ in 0..3000 {
                let mut r: Vec<C64> = (0..problem.dim - 1)
                    .map(|_| C64::from_polar(1.0, rng.random::<f64>() * TAU))
                    .collect();
                r.push(C64::new(1.0, 0.0));
                let value = rate_of(&problem, &model, &r);
                assert!(
                    value <= bound + 1e-9,
                    "{access:?}: random {value} > bound {bound}"
                );
                best_random = best_random.max(value);
            }
            assert!(
                achieved >= best_random - 1e-9,
                "{access:?}: fast {achieved} < random {best_random}"
            );
        }
    }
}

/// K = 2 SRUs: the generalised solver still meets every SRU and stays under its bound.
#[test]
fn two_static_robots() {
    let s = small(|v| {
        v["srus"] = serde_json::json!([
            {"position": [5.5, 3.5, 1.2], "min_rate_bps_hz": 0.5},
            {"position": [0.5, 0.5, 1.2], "min_rate_bps_hz": 0.5}
        ]);
    });
    for access in [Access::Noma, Access::Oma] {
        for (problem, model) in problems(&s, access, 6, 3) {
            let v = fast::solve(&problem, &model);
            let achieved = rate_of(&problem, &model, &v);
            assert!(achieved.is_finite());
            assert!(
                certificate::certify(&problem, &model, Some(&v)).upper_bound >= achieved - 1e-9
            );
            let mut lambdas = vec![0.0; 3];
            problem.lambdas(&v, &mut lambdas);
            let split = model.best(&lambdas).unwrap();
            let rates = model.rates(&lambdas, &split.power_w, split.order as usize);
            assert!(
                rates[1] >= 0.5 - 1e-9 && rates[2] >= 0.5 - 1e-9,
                "{rates:?}"
            );
        }
    }
}

/// Issue 36: the paper's multi-user floor with 2 and 3 SRUs (the paper's SRU plus SRUs at
/// (−8, −8) and (8, −8) wanting 0.5 bit/s/Hz), at 1 m: the certificate's gap has median
/// ≤ 1e-4 bit/s/Hz and max ≤ 1e-2 (K = 2) or 5e-2 (K = 3), the joint relaxation's own limit
/// (at 0.5 m the medians are 8e-9 and 2e-6, the maxima 2.4e-3 and 2.1e-2; docs/model.md §5),
/// and the bound is above the value in every cell. The per-user bound this replaced had
/// medians of 0.077 and 0.12.
#[test]
fn multi_user_cells_are_certified() {
    for (srus, max_gap) in [(2usize, 1e-2), (3, 5e-2)] {
        let s = Scenario::builtin_with("paper-multi-user", |v| {
            v["grid"]["resolution_m"] = 1.0.into();
            let list = v["srus"].as_array_mut().unwrap();
            for p in [[-8.0, -8.0, 1.3], [8.0, -8.0, 1.3]].iter().take(srus - 1) {
                list.push(serde_json::json!({"position": p, "min_rate_bps_hz": 0.5}));
            }
        })
        .unwrap()
        .unwrap();
        for access in [Access::Noma, Access::Oma] {
            let key = MapKey::new("t", &s, MapKind::Rate, None, Some(access), None).unwrap();
            let map = irs_answers::map::build(&s, &key, &Progress::default()).unwrap();
            let summary = map.certificate_summary().unwrap();
            let (median, max) = (summary.median_gap.unwrap(), summary.max_gap.unwrap());
            assert!(summary.cells > 250, "{} cells", summary.cells);
            assert!(
                median <= 1e-4 && max <= max_gap,
                "{srus} SRUs, {access:?}: median gap {median}, max {max}"
            );
            for (value, bound) in map.values.iter().zip(map.upper_bound().unwrap()) {
                assert!(
                    value.is_nan() || *bound >= value - 1e-9,
                    "{bound} < {value}"
                );
            }
        }
    }
}

/// Discrete phases: never better than continuous, and every phase on the 2^b grid.
#[test]
fn discrete_rate_phases_lie_on_the_grid() {
    let s = small(|_| {});
    for (problem, model) in problems(&s, Access::Noma, 6, 8) {
        let continuous = rate_of(&problem, &model, &fast::solve(&problem, &model));
        let sol = solver::solve_cell(&problem, &model, PhaseMode::Bits(2), SolverKind::Fast);
        assert!(sol.rate <= continuous + 1e-9);
        for theta in solver::phases_of(&sol.v) {
            let level = theta / (TAU / 4.0);
            assert!(
                (level - level.round()).abs() < 1e-9,
                "{theta} is not a 2-bit level"
            );
        }
    }
}

/// Paper Fig. 10: along a planned path, the Monte Carlo mean of the exact rates is below the
/// Jensen bound (up to 3 standard errors), for the MRU and the SRU; on gain maps the mean of
/// |c|² equals λ within 3 standard errors.
#[test]
fn monte_carlo_means_respect_the_jensen_bound() {
    let s = small(|_| {});
    for (kind, access) in [
        (MapKind::Rate, Some(Access::Noma)),
        (MapKind::Rate, Some(Access::Oma)),
        (MapKind::Gain, None),
    ] {
        let key = MapKey::new("t", &s, kind, None, access, None).unwrap();
        let map = irs_answers::map::build(&s, &key, &Progress::default()).unwrap();
        let path = planner::plan(
            &map,
            map.native_unit(),
            Default::default(),
            [0.5, 0.5],
            [5.5, 3.0],
            Threshold::Max,
            1.0,
        )
        .unwrap();
        assert!(path.feasible);
        let report =
            montecarlo::check_path(&s, &map, &path, 20_000, 7, &Progress::default()).unwrap();
        assert_eq!(report.waypoints.len(), path.waypoints.len());
        for wp in &report.waypoints {
            for u in &wp.users {
                match kind {
                    MapKind::Rate => assert!(
                        u.monte_carlo_mean <= u.bound + 3.0 * u.std_error,
                        "{:?} {}: MC {} ± {} vs bound {}",
                        access,
                        u.user,
                        u.monte_carlo_mean,
                        u.std_error,
                        u.bound
                    ),
                    MapKind::Gain => assert!(u.gap.abs() <= 3.0 * u.std_error + 1e-9, "{u:?}"),
                }
            }
        }
        if kind == MapKind::Rate {
            // The MRU's Jensen gap is positive somewhere (the bound is not an identity).
            assert!(
                report
                    .max_gap
                    .iter()
                    .any(|u| u.user == "mru" && u.gap > 0.0)
            );
        }
    }
}

#[cfg(feature = "sdp")]
mod sdp {
    use super::*;
    use irs_model::solver::sdr_sca;

    /// The joint support bound (3–5 users) equals Clarabel's SDP optimum within 1e-4 relative.
    #[test]
    fn joint_support_bound_matches_clarabel() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(22);
        for case in 0..9 {
            let (users, dim) = (3 + case % 3, rng.random_range(3..9));
            let a: Vec<Vec<C64>> = (0..users)
                .map(|_| {
                    (0..dim)
                        .map(|_| C64::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5))
                        .collect()
                })
                .collect();
            let w: Vec<f64> = (0..users).map(|_| rng.random::<f64>() + 0.05).collect();
            let exact = sdr_sca::support_value(&a, &w).expect("Clarabel solves the SDP");
            let problem = CellProblem {
                dim,
                a: a.iter().flatten().copied().collect(),
                tau: vec![0.0; users],
            };
            let bound = certificate::joint_support_bound(&problem, &w);
            assert!(
                (bound - exact).abs() <= 1e-4 * exact,
                "{users} users: bound {bound} vs Clarabel {exact}"
            );
        }
    }

    /// K = 2 and 3 SRUs: the joint bound is at least the relaxation's value from Clarabel's
    /// bisection (it is valid) and at most that plus the bisection's tolerance and 1e-3 (it is
    /// the relaxation's value, not a looser one); `fast` meets the relaxation's SCA primal.
    #[test]
    fn the_joint_bound_is_the_relaxations_value() {
        for srus in [2usize, 3] {
            let s = small(|v| {
                v["irs"]["nx_sub"] = 2.into();
                v["irs"]["nz_sub"] = 2.into();
                let all = serde_json::json!([
                    {"position": [5.5, 3.5, 1.2], "min_rate_bps_hz": 0.5},
                    {"position": [0.5, 0.5, 1.2], "min_rate_bps_hz": 0.5},
                    {"position": [3.0, 3.8, 1.2], "min_rate_bps_hz": 0.3}
                ]);
                v["srus"] = serde_json::Value::Array(all.as_array().unwrap()[..srus].to_vec());
            });
            for access in [Access::Noma, Access::Oma] {
                for (problem, model) in problems(&s, access, 2, 40 + srus as u64) {
                    let cell = solver::solve_cell(
                        &problem,
                        &model,
                        PhaseMode::Continuous,
                        SolverKind::Fast,
                    );
                    let (fast_rate, bound) = (cell.rate, cell.upper_bound);
                    let sdr = sdr_sca::solve(&problem, &model);
                    let sdr_rate = rate_of(&problem, &model, &sdr.v);
                    assert!(
                        bound >= sdr.relaxed_rate - 1e-6,
                        "{srus} SRUs, {access:?}: bound {bound} < SDR {}",
                        sdr.relaxed_rate
                    );
                    assert!(
                        bound <= sdr.relaxed_rate + 1e-4 + 1e-3,
                        "{srus} SRUs, {access:?}: bound {bound} ≫ SDR {}",
                        sdr.relaxed_rate
                    );
                    assert!(fast_rate >= sdr_rate - 1e-3 && fast_rate <= bound + 1e-9);
                }
            }
        }
    }

    /// The solver-free support bound equals Clarabel's SDP optimum within 1e-4 relative.
    #[test]
    fn support_bound_matches_clarabel() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(21);
        for _ in 0..12 {
            let n = rng.random_range(3..9);
            let vec = |rng: &mut rand::rngs::StdRng| -> Vec<C64> {
                (0..n)
                    .map(|_| C64::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5))
                    .collect()
            };
            let (a, b) = (vec(&mut rng), vec(&mut rng));
            let angle = rng.random::<f64>() * std::f64::consts::FRAC_PI_2;
            let (w1, w2) = (angle.cos(), angle.sin());
            let exact = sdr_sca::support_value(&[a.clone(), b.clone()], &[w1, w2])
                .expect("Clarabel solves the SDP");
            let bound = certificate::support_bound(&a, &b, w1, w2);
            assert!(
                (bound - exact).abs() <= 1e-4 * exact,
                "bound {bound} vs Clarabel {exact}"
            );
        }
    }

    /// N ≤ 10: `fast` ≥ `sdr-sca` − 0.001 bit/s/Hz, and both ≤ the certificate.
    #[test]
    fn fast_matches_the_papers_sdr_sca() {
        let s = small(|v| {
            v["irs"]["nx_sub"] = 3.into();
            v["irs"]["nz_sub"] = 2.into();
        });
        for access in [Access::Noma, Access::Oma] {
            for (problem, model) in problems(&s, access, 3, 17) {
                let fast_rate = rate_of(&problem, &model, &fast::solve(&problem, &model));
                let sdr = sdr_sca::solve(&problem, &model);
                let sdr_rate = rate_of(&problem, &model, &sdr.v);
                let bound = certificate::certify(&problem, &model, None).upper_bound;
                assert!(
                    fast_rate >= sdr_rate - 1e-3,
                    "{access:?}: fast {fast_rate} < sdr-sca {sdr_rate}"
                );
                assert!(sdr_rate <= bound + 1e-9 && fast_rate <= bound + 1e-9);
                // The bisection's relaxed value is itself an SDR bound; ours must not be looser
                // than it by more than the bisection tolerance plus the polygon's slack.
                assert!(
                    bound >= sdr.relaxed_rate - 1e-3,
                    "bound {bound} < SDR {}",
                    sdr.relaxed_rate
                );
            }
        }
    }
}
