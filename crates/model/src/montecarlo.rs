//! Monte Carlo check of a planned path (paper Section IV-B4, Fig. 10).
//!
//! The maps use Jensen upper bounds of the expected rates (eqs. 22 and 24) and the closed-form
//! expected gain (Lemma 1, eq. 5). Here, for each waypoint, the exact instantaneous rates
//! (eqs. 21/23) — or, on gain maps, the instantaneous power gain |c|² — are averaged over Rician
//! draws of the per-element channel (paper eqs. 1–4) with the waypoint's θ, power split and
//! decoding order,
//! and compared with the bound. The draws are independent of the closed forms: they reuse only
//! the geometry and the LoS phases.

use crate::channel::ChannelModel;
use crate::numerics::MeanEstimate;
use crate::planner::PathAnswer;
use crate::radiomap::{Cancelled, CellSolutions, Progress, RadioMap};
use crate::rate::user_label;
use crate::scenario::Scenario;
use rand::SeedableRng;
use rayon::prelude::*;
use serde::Serialize;

/// Largest number of draws per waypoint accepted.
pub const MAX_DRAWS: usize = 1_000_000;

/// Seconds of one core per (waypoint · draw · element · user): each element of each draw takes
/// two complex Gaussian draws and a rotation (measured ~12 ns on the project's machine; rounded
/// up so the estimate errs on the side of refusing).
const CHECK_S_PER_ELEMENT_DRAW: f64 = 20e-9;

/// Estimated seconds of one core to check `waypoints` waypoints with `draws` draws each on a
/// map of `scenario` (`rate`: the SRUs are drawn too), for a service's budget check before the
/// work starts.
pub fn check_seconds(scenario: &Scenario, waypoints: usize, draws: usize, rate: bool) -> f64 {
    let elements: f64 = scenario
        .surfaces()
        .iter()
        .map(|s| s.elements() as f64)
        .sum();
    let users = if rate { 1 + scenario.srus.len() } else { 1 };
    waypoints as f64 * draws as f64 * (1.0 + elements) * users as f64 * CHECK_S_PER_ELEMENT_DRAW
}

/// One user at one waypoint.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct UserCheck {
    /// Which user: "mru" or "sru{k}" ([`user_label`]).
    pub user: String,
    /// Rate maps: the Jensen-bound rate (bit/s/Hz); gain maps: λ = E|c|² (dB).
    pub bound: f64,
    /// The Monte Carlo mean of the same quantity (rate, or |c|² in dB of the mean).
    pub monte_carlo_mean: f64,
    /// Standard error of the Monte Carlo mean (same unit; for dB, of the linear mean, in dB).
    pub std_error: f64,
    /// bound − mean: the Jensen gap (≥ 0 up to sampling noise for rates, ≈ 0 for gains).
    pub gap: f64,
}

/// The check of one waypoint of the path.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WaypointCheck {
    /// The waypoint's cell index along x.
    pub i: usize,
    /// The waypoint's cell index along y.
    pub j: usize,
    /// One entry per user: the MRU alone on a gain map, then the SRUs on a rate map.
    pub users: Vec<UserCheck>,
}

/// The Monte Carlo check of a path (docs/model.md §8): per waypoint and user, bound vs mean.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MonteCarloReport {
    /// Channel draws per waypoint.
    pub draws: usize,
    /// Seed of the generators; waypoint k draws from `seed + k`, so a report is reproducible.
    pub seed: u64,
    /// Largest gap per user over the path.
    pub max_gap: Vec<UserCheck>,
    /// One entry per waypoint, in path order.
    pub waypoints: Vec<WaypointCheck>,
}

/// Runs the check for every waypoint of a feasible path (waypoints in parallel, each with its
/// own seeded generator, so the report is reproducible): the waypoint's configuration at its
/// cell's centre, against the map's value there (in the map's own unit, whatever the query's). `progress` counts the waypoints done;
/// cancelling it stops the check before the next waypoint.
pub fn check_path(
    scenario: &Scenario,
    map: &RadioMap,
    path: &PathAnswer,
    draws: usize,
    seed: u64,
    progress: &Progress,
) -> Result<MonteCarloReport, Cancelled> {
    // Gain maps: each waypoint is checked against the AP serving it. Rate maps have one AP.
    let channels: Vec<ChannelModel> = (0..scenario.access_points().len())
        .map(|ap| ChannelModel::for_ap(scenario, ap))
        .collect();
    let channel = &channels[0];
    let height = scenario.mru.antenna_height_m;
    // Rate maps: the users' expected gains at a waypoint's phases, the SRUs' part worked out
    // once per path.
    let evaluator = map.rate_evaluator(scenario);
    progress.start(path.waypoints.len());
    let waypoints: Vec<WaypointCheck> = path
        .waypoints
        .par_iter()
        .enumerate()
        .map(|(k, wp)| {
            if progress.is_cancelled() {
                return Err(Cancelled);
            }
            let mut rng = rand::rngs::StdRng::seed_from_u64(seed.wrapping_add(k as u64));
            // At the cell's centre, against the map's own value there: the waypoint may lie on
            // the cell's side (any-angle routes) and its value may be in another unit.
            let [x, y] = map.grid.centre(wp.i, wp.j);
            let mru = [x, y, height];
            let cell = map.grid.index(wp.i, wp.j);
            // The gain the serving AP gives there: the map's value unless another AP (of a
            // weaker budget) has the better channel (docs/model.md §3).
            let bound = match &map.cells {
                CellSolutions::Gain {
                    serving_gain_db, ..
                } if !serving_gain_db.is_empty() => serving_gain_db[cell],
                _ => map.values[cell],
            };
            let theta = wp.config.concatenated_phases();
            let theta_opt = (!theta.is_empty()).then_some(theta.as_slice());
            let users = match &map.cells {
                CellSolutions::Gain { .. } => {
                    let mut power_gain = MeanEstimate::default();
                    channels[wp.config.ap].sample_channels(
                        &[mru],
                        theta_opt,
                        draws,
                        &mut rng,
                        |c| {
                            power_gain.add(c[0].norm_sqr());
                        },
                    );
                    let (mean, se) = (power_gain.mean(), power_gain.std_error());
                    let mean_db = 10.0 * mean.log10();
                    vec![UserCheck {
                        user: user_label(0),
                        bound,
                        monte_carlo_mean: mean_db,
                        std_error: 10.0 * (1.0 + se / mean).log10(),
                        gap: bound - mean_db,
                    }]
                }
                CellSolutions::Rate(rate) => {
                    let model = rate.rate_model();
                    let cell = map.grid.index(wp.i, wp.j);
                    let order = rate.order(cell);
                    let power = wp
                        .config
                        .power_w
                        .as_ref()
                        .expect("rate waypoints carry powers");
                    let evaluator = evaluator.as_ref().expect("a rate map has one");
                    let bounds = model.rates(&evaluator.gains(cell, &theta), power, order);
                    let mut positions = vec![mru];
                    positions.extend(scenario.srus.iter().map(|s| s.position));
                    let mut rates = vec![MeanEstimate::default(); model.users()];
                    let mut gains = vec![0.0; model.users()];
                    channel.sample_channels(&positions, theta_opt, draws, &mut rng, |c| {
                        for (g, x) in gains.iter_mut().zip(c) {
                            *g = x.norm_sqr();
                        }
                        for (estimate, r) in rates.iter_mut().zip(model.rates(&gains, power, order))
                        {
                            estimate.add(r);
                        }
                    });
                    rates
                        .iter()
                        .enumerate()
                        .map(|(l, estimate)| UserCheck {
                            user: user_label(l),
                            bound: bounds[l],
                            monte_carlo_mean: estimate.mean(),
                            std_error: estimate.std_error(),
                            gap: bounds[l] - estimate.mean(),
                        })
                        .collect()
                }
            };
            progress.advance(1);
            Ok(WaypointCheck {
                i: wp.i,
                j: wp.j,
                users,
            })
        })
        .collect::<Result<_, Cancelled>>()?;
    let mut max_gap: Vec<UserCheck> = Vec::new();
    for wp in &waypoints {
        for u in &wp.users {
            match max_gap.iter_mut().find(|m| m.user == u.user) {
                Some(m) if m.gap >= u.gap => {}
                Some(m) => *m = u.clone(),
                None => max_gap.push(u.clone()),
            }
        }
    }
    Ok(MonteCarloReport {
        draws,
        seed,
        max_gap,
        waypoints,
    })
}
