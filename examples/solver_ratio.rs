//! Per-cell time of the `fast` solver versus the paper's SDR+SCA (Clarabel) on the same small
//! instance, measured in one run, with both rates and the certificate.
//!
//! `cargo run --release --features sdp --example solver_ratio [N_X N_Z]` (default 5 × 2, N = 10).

use irs_answers::scenario::ScenarioDocument;
use irs_model::channel::ChannelModel;
use irs_model::rate::{Access, RateModel};
use irs_model::scenario::Scenario;
use irs_model::solver::{self, certificate, fast, objective, sdr_sca};
use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let (nx, nz) = (
        args.first().copied().unwrap_or(5),
        args.get(1).copied().unwrap_or(2),
    );
    let s = Scenario::builtin_with("paper-multi-user", |v| {
        v["irs"]["nx_sub"] = nx.into();
        v["irs"]["nz_sub"] = nz.into();
    })
    .expect("built in")
    .expect("a valid IRS size");
    let channel = ChannelModel::new(&s);
    let srus = solver::sru_part(&channel, &s, true);
    println!("N = {} sub-surfaces, paper multi-user geometry", nx * nz);
    println!(
        "{:>6} {:>10} {:>12} {:>12} {:>12} {:>12} {:>10}",
        "access", "cell", "fast rate", "sdr-sca rate", "bound", "fast s", "ratio"
    );
    for access in [Access::Noma, Access::Oma] {
        let model = RateModel::for_scenario(&s, access);
        for cell in [[-10.0, 0.0], [3.0, -6.0], [6.0, 8.0]] {
            let problem = solver::cell_problem(&channel, [cell[0], cell[1], 1.0], &srus, true);
            let rate = |v: &[irs_model::channel::C64]| {
                let mut l = vec![0.0; problem.users()];
                problem.lambdas(v, &mut l);
                objective(&model, &l)
            };
            let reps = 200;
            let t = Instant::now();
            let mut v_fast = Vec::new();
            for _ in 0..reps {
                v_fast = fast::solve(&problem, &model);
            }
            let fast_s = t.elapsed().as_secs_f64() / reps as f64;
            let t = Instant::now();
            let sdr = sdr_sca::solve(&problem, &model);
            let sdr_s = t.elapsed().as_secs_f64();
            println!(
                "{:>6} {:>10} {:>12.5} {:>12.5} {:>12.5} {:>12.2e} {:>9.0}×   (sdr-sca {:.2} s)",
                format!("{access:?}").to_lowercase(),
                format!("{},{}", cell[0], cell[1]),
                rate(&v_fast),
                rate(&sdr.v),
                certificate::certify(&problem, &model, Some(&v_fast)).upper_bound,
                fast_s,
                sdr_s / fast_s,
                sdr_s
            );
        }
    }
}
