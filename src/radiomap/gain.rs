//! Channel power gain maps (docs/model.md §3): per free cell max_θ λ(θ) in dB, for the phase
//! modes `continuous` (closed form, eq. 12, attained by eq. 11's phases), `bits: b` (eq. 11's
//! phases quantised to L = 2^b levels, eq. 43) and `none` (the direct link alone).
//!
//! Maps keep no phases: θ* of a waypoint is recomputed in O(N) from the channel model
//! ([`waypoint_phases`]) instead of storing N floats per cell (a 1001² map at N = 60 would
//! otherwise hold 480 MB of phases).

use super::{Cancelled, Progress};
use crate::channel::{C64, ChannelModel, expected_gain};
use crate::numerics::l1_norm;
use crate::phases::{PhaseMode, phases_for_mode};
use crate::scenario::Grid;
use rayon::prelude::*;

/// The best expected gain λ (linear) at `user` for a phase mode, using the buffers `w` (N) and
/// `theta` (N): `continuous`: (|h̃| + ‖w̃‖₁)² + τ (eq. 12); `bits`: λ (eq. 6) at the quantised
/// eq. 11 phases (eq. 43); `none`: |h̃|² + τ of the direct link alone.
pub fn best_gain(
    model: &ChannelModel,
    user: [f64; 3],
    mode: PhaseMode,
    w: &mut [C64],
    theta: &mut [f64],
) -> f64 {
    let direct = model.evaluate(user, mode != PhaseMode::None, w);
    match mode {
        PhaseMode::None => direct.h.norm_sqr() + direct.tau,
        PhaseMode::Continuous => (direct.h.norm() + l1_norm(w)).powi(2) + direct.tau,
        PhaseMode::Bits(_) => {
            phases_for_mode(model, user, mode, theta);
            expected_gain(&direct, w, theta)
        }
    }
}

/// The map values in dB (NaN where occupied). Rows of the grid are spread over rayon's pool;
/// progress advances and cancellation is checked once per row.
pub(super) fn gain_values(
    model: &ChannelModel,
    grid: &Grid,
    occupied: &[bool],
    height: f64,
    mode: PhaseMode,
    progress: &Progress,
) -> Result<Vec<f64>, Cancelled> {
    let mut values = vec![f64::NAN; grid.cells()];
    values
        .par_chunks_mut(grid.ny)
        .zip(occupied.par_chunks(grid.ny))
        .enumerate()
        .try_for_each_init(
            || {
                (
                    vec![C64::new(0.0, 0.0); model.subsurfaces()],
                    vec![0.0; model.subsurfaces()],
                )
            },
            |(w, theta), (i, (row, occupied_row))| {
                if progress.is_cancelled() {
                    return Err(Cancelled);
                }
                for (j, (value, &occ)) in row.iter_mut().zip(occupied_row).enumerate() {
                    if occ {
                        continue;
                    }
                    let [x, y] = grid.centre(i, j);
                    *value = 10.0 * best_gain(model, [x, y, height], mode, w, theta).log10();
                }
                progress.advance(row.len());
                Ok(())
            },
        )?;
    Ok(values)
}

/// The phases to apply at a waypoint of a gain map: θ* of eq. 11 (quantised for `bits`), none
/// for `none`.
pub(super) fn waypoint_phases(model: &ChannelModel, user: [f64; 3], mode: PhaseMode) -> Vec<f64> {
    let n = if mode == PhaseMode::None {
        0
    } else {
        model.subsurfaces()
    };
    let mut phases = vec![0.0; n];
    if n > 0 {
        phases_for_mode(model, user, mode, &mut phases);
    }
    phases
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radiomap::{MapKey, build};
    use crate::scenario::{Grouping, Scenario};
    use rand::{RngExt, SeedableRng};
    use std::f64::consts::TAU;

    fn gain_key(s: &Scenario, phases: PhaseMode) -> MapKey {
        MapKey::gain("test", s, phases).unwrap()
    }

    /// The closed form (eq. 12) is at least the best of many random θ, equals λ at the eq. 11
    /// phases, and is the triangle-inequality bound (eq. 10) that no θ exceeds.
    #[test]
    fn closed_form_beats_random_phases_and_meets_the_bound() {
        for grouping in [Grouping::Coherent, Grouping::Elements] {
            let s = Scenario::small_test_grouped(grouping);
            let model = ChannelModel::new(&s);
            let mut rng = rand::rngs::StdRng::seed_from_u64(3);
            let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
            let mut theta = vec![0.0; w.len()];
            for _ in 0..40 {
                let q = [rng.random_range(0.0..6.0), rng.random_range(0.2..4.0), 1.0];
                let d = model.evaluate(q, true, &mut w);
                let best = best_gain(&model, q, PhaseMode::Continuous, &mut w, &mut theta);
                let bound = (d.h.norm() + l1_norm(&w)).powi(2) + d.tau;
                assert!((best - bound).abs() <= 1e-12 * bound);
                // Eq. 11's phases (from distances) attain the closed form.
                model.optimal_phases(q, &mut theta);
                assert!(
                    (expected_gain(&d, &w, &theta) / best - 1.0).abs() < 1e-12,
                    "{grouping:?} at {q:?}"
                );
                for _ in 0..500 {
                    let random: Vec<f64> =
                        (0..w.len()).map(|_| rng.random::<f64>() * TAU).collect();
                    assert!(expected_gain(&d, &w, &random) <= best * (1.0 + 1e-12));
                }
            }
        }
    }

    #[test]
    fn quantised_phases_never_beat_continuous_and_none_is_the_direct_link() {
        let s = Scenario::builtin("small-test").unwrap();
        let progress = Progress::default();
        let cont = build(&s, &gain_key(&s, PhaseMode::Continuous), &progress).unwrap();
        let none = build(&s, &gain_key(&s, PhaseMode::None), &progress).unwrap();
        let model = ChannelModel::new(&s);
        for b in 1..=3 {
            let q = build(&s, &gain_key(&s, PhaseMode::Bits(b)), &progress).unwrap();
            for (a, c) in q.values.iter().zip(&cont.values) {
                assert!(
                    a.is_nan() && c.is_nan() || a <= &(c + 1e-9),
                    "{b} bits: {a} > {c}"
                );
            }
        }
        let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
        for (k, v) in none.values.iter().enumerate() {
            if none.occupied[k] {
                assert!(v.is_nan());
                continue;
            }
            let (i, j) = none.grid.cell_of(k);
            let [x, y] = none.grid.centre(i, j);
            let d = model.evaluate([x, y, s.mru.antenna_height_m], false, &mut w);
            let direct_db = 10.0 * (d.h.norm_sqr() + d.tau).log10();
            assert!((v - direct_db).abs() < 1e-9);
            assert!(*v <= cont.values[k] + 1e-9);
        }
        assert_eq!(progress.cells_done(), progress.cells_total());
    }

    #[test]
    fn cancellation_stops_a_build() {
        let s = Scenario::builtin("small-test").unwrap();
        let progress = Progress::default();
        progress.cancel();
        let r = build(&s, &gain_key(&s, PhaseMode::Continuous), &progress);
        assert_eq!(r.unwrap_err(), Cancelled);
    }
}
