//! Channel power gain maps (docs/model.md §3): per free cell max_θ λ(θ) in dB, for the phase
//! modes `continuous` (closed form, eq. 12, attained by eq. 11's phases), `bits: b` (eq. 11's
//! phases quantised to L = 2^b levels, eq. 43) and `none` (the direct link alone).
//!
//! Maps keep no phases: θ* of a waypoint is recomputed in O(N) from the channel model
//! ([`waypoint_phases`]) instead of storing N floats per cell (a 1001² map at N = 60 would
//! otherwise hold 480 MB of phases).

use super::{Cancelled, Progress};
use crate::channel::{C64, ChannelModel, ClosedFormRow, RowTerms, expected_gain};
use crate::phases::{PhaseMode, phases_for_mode};
use crate::scenario::Grid;
use crate::vecmath;
use rayon::prelude::*;

/// The best expected gain λ (linear) at `user` for a phase mode, using the buffers `w` (N) and
/// `theta` (N): `continuous`: (|h̃| + ‖w̃‖₁)² + τ (eq. 12), without forming w̃ for `coherent`
/// surfaces; `bits`: λ (eq. 6) at the quantised eq. 11 phases (eq. 43); `none`: |h̃|² + τ of
/// the direct link alone.
pub fn best_gain(
    model: &ChannelModel,
    user: [f64; 3],
    mode: PhaseMode,
    w: &mut [C64],
    theta: &mut [f64],
) -> f64 {
    match mode {
        // O(1) per coherent surface: ‖w̃_s‖₁ from one link budget (ChannelModel docs).
        PhaseMode::Continuous => {
            let terms = model.closed_form_terms(user, w);
            (terms.direct_amplitude + terms.l1).powi(2) + terms.tau
        }
        PhaseMode::None => {
            let direct = model.direct(user);
            direct.h.norm_sqr() + direct.tau
        }
        PhaseMode::Bits(_) => {
            let direct = model.evaluate(user, true, w);
            phases_for_mode(model, user, mode, theta);
            expected_gain(&direct, w, theta)
        }
    }
}

/// What [`gain_values`] computes per cell.
pub(super) struct GainValues {
    /// The best AP's gain (dB), NaN where occupied: the map's values.
    pub values: Vec<f64>,
    /// The serving AP of each cell (empty with one AP).
    pub serving: Vec<u8>,
    /// The serving AP's gain (dB) where it differs from the best; empty when the AP of best
    /// gain serves every cell.
    pub serving_gain_db: Vec<f64>,
}

/// The map values in dB (NaN where occupied) and, with several APs, the AP serving each cell:
/// the one received strongest there (its optimised gain plus its link budget `offsets_db`, all
/// IRSs configured for it), which need not be the one of best gain when transmit powers differ
/// (docs/model.md §3). Rows of the grid are spread over rayon's pool; progress advances once per
/// row, and cancellation is checked once per row (a row at a time) or per cell (cell by cell).
/// The continuous closed form over `coherent` surfaces is evaluated a row at a time
/// ([`ChannelModel::closed_form_row`]); other modes cell by cell.
pub(super) fn gain_values(
    models: &[ChannelModel],
    offsets_db: &[f64],
    grid: &Grid,
    occupied: &[bool],
    height: f64,
    mode: PhaseMode,
    progress: &Progress,
) -> Result<GainValues, Cancelled> {
    let mut values = vec![f64::NAN; grid.cells()];
    // With one AP it serves every cell at the best gain: the serving AP and its gain are never
    // written, and their zeroed pages (calloc's) never touched. Working them out anyway (a
    // second array filled, a second logarithm a cell, the two compared) was 17 % of the paper
    // floor's build at 2 cm on one thread (scripts/vs_kernel.py: 46.1 → 38.2 ms).
    let single = models.len() == 1;
    let mut serving = vec![0u8; grid.cells()];
    let mut serving_gain = if single {
        vec![0.0; grid.cells()]
    } else {
        vec![f64::NAN; grid.cells()]
    };
    // Each AP's budget relative to the first, linear: the received power compared is λ·weight.
    let weights: Vec<f64> = offsets_db
        .iter()
        .map(|o| 10f64.powf((o - offsets_db[0]) / 10.0))
        .collect();
    let rows = values
        .par_chunks_mut(grid.ny)
        .zip(occupied.par_chunks(grid.ny))
        .zip(serving.par_chunks_mut(grid.ny))
        .zip(serving_gain.par_chunks_mut(grid.ny))
        .enumerate();
    let db_per_neper = 10.0 * std::f64::consts::LOG10_E;
    if mode == PhaseMode::Continuous && models.iter().all(|m| m.closed_form_by_rows()) {
        rows.try_for_each_init(
            ClosedFormRow::default,
            |row, (i, (((values_row, occupied_row), serving_row), serving_gain_row))| {
                if progress.is_cancelled() {
                    return Err(Cancelled);
                }
                let x = grid.x_min + i as f64 * grid.resolution_m;
                // λ of the best AP and of the serving one so far, in place of their dB values
                // until the last AP is seen.
                for (k, model) in models.iter().enumerate() {
                    model.closed_form_row(
                        RowTerms::All,
                        x,
                        grid.y_min,
                        grid.resolution_m,
                        height,
                        occupied_row,
                        row,
                    );
                    let terms = row.amplitude.iter().zip(&row.tau);
                    if single {
                        for (best, (a, t)) in values_row.iter_mut().zip(terms) {
                            *best = a * a + t;
                        }
                        continue;
                    }
                    let cells = values_row
                        .iter_mut()
                        .zip(serving_row.iter_mut())
                        .zip(serving_gain_row.iter_mut());
                    for (((best, ap), at_ap), (a, t)) in cells.zip(terms) {
                        let gain = a * a + t;
                        if k == 0 || gain > *best {
                            *best = gain;
                        }
                        if k == 0 || gain * weights[k] > *at_ap * weights[usize::from(*ap)] {
                            (*at_ap, *ap) = (gain, k as u8);
                        }
                    }
                }
                let in_db = |part: &mut [f64]| {
                    vecmath::ln_in_place(part);
                    for (value, &occ) in part.iter_mut().zip(occupied_row) {
                        *value = if occ { f64::NAN } else { *value * db_per_neper };
                    }
                };
                in_db(values_row);
                if !single {
                    in_db(serving_gain_row);
                }
                progress.advance(values_row.len());
                Ok(())
            },
        )?;
    } else {
        let n = models.first().map_or(0, |m| m.subsurfaces());
        rows.try_for_each_init(
            || (vec![C64::new(0.0, 0.0); n], vec![0.0; n]),
            |(w, theta), (i, (((row, occupied_row), serving_row), serving_gain_row))| {
                if progress.is_cancelled() {
                    return Err(Cancelled);
                }
                for (j, (value, &occ)) in row.iter_mut().zip(occupied_row).enumerate() {
                    if occ {
                        continue;
                    }
                    // A cell of 200 000 elements costs milliseconds, a row of them seconds: a
                    // cancel is honoured per cell here (one relaxed load).
                    if progress.is_cancelled() {
                        return Err(Cancelled);
                    }
                    let [x, y] = grid.centre(i, j);
                    let user = [x, y, height];
                    let (mut best, mut received, mut at_ap, mut ap) =
                        (f64::NEG_INFINITY, f64::NEG_INFINITY, 0.0, 0);
                    for (k, model) in models.iter().enumerate() {
                        let gain = best_gain(model, user, mode, w, theta);
                        best = best.max(gain);
                        if gain * weights[k] > received {
                            (received, at_ap, ap) = (gain * weights[k], gain, k);
                        }
                    }
                    *value = 10.0 * best.log10();
                    if !single {
                        serving_gain_row[j] = 10.0 * at_ap.log10();
                        serving_row[j] = ap as u8;
                    }
                }
                progress.advance(row.len());
                Ok(())
            },
        )?;
    }
    let differs = !single
        && values
            .iter()
            .zip(&serving_gain)
            .any(|(v, g)| v.to_bits() != g.to_bits());
    if single {
        // One AP serves every cell: nothing to keep.
        serving = Vec::new();
    }
    if !differs {
        serving_gain = Vec::new();
    }
    Ok(GainValues {
        values,
        serving,
        serving_gain_db: serving_gain,
    })
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
    use crate::numerics::l1_norm;
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

    /// Whole maps: the closed form without w̃ gives the per-sub-surface evaluation (w̃ formed,
    /// then ‖w̃‖₁) in every cell to 1e-9 dB, for one and two surfaces, both groupings and two
    /// APs.
    #[test]
    fn map_cells_match_the_per_subsurface_evaluation() {
        let paper = Scenario::builtin("paper-single-user").unwrap();
        let two_aps = paper
            .with_access_points(vec![paper.ap().clone(), {
                let mut ap = paper.ap().clone();
                ap.position = [8.0, 8.0, 2.5];
                ap
            }])
            .unwrap();
        let scenarios = [
            paper,
            two_aps,
            Scenario::small_test_two_surfaces(Grouping::Coherent),
            Scenario::small_test_two_surfaces(Grouping::Elements),
        ];
        for s in scenarios {
            let map = build(
                &s,
                &gain_key(&s, PhaseMode::Continuous),
                "test".into(),
                &Progress::default(),
            )
            .unwrap();
            let models: Vec<ChannelModel> = (0..s.access_points().len())
                .map(|k| ChannelModel::for_ap(&s, k))
                .collect();
            let mut w = vec![C64::new(0.0, 0.0); models[0].subsurfaces()];
            for (index, value) in map.values.iter().enumerate() {
                if map.occupied[index] {
                    continue;
                }
                let (i, j) = map.grid.cell_of(index);
                let [x, y] = map.grid.centre(i, j);
                let reference = models
                    .iter()
                    .map(|m| {
                        let d = m.evaluate([x, y, s.mru.antenna_height_m], true, &mut w);
                        (d.h.norm() + l1_norm(&w)).powi(2) + d.tau
                    })
                    .fold(f64::NEG_INFINITY, f64::max);
                let reference_db = 10.0 * reference.log10();
                assert!(
                    (value - reference_db).abs() <= 1e-9,
                    "{:?} cell ({i}, {j}): {value} vs {reference_db}",
                    s.name
                );
            }
        }
    }

    /// Two IRSs: the closed form is exactly (|h̃| + ‖w̃₁‖₁ + ‖w̃₂‖₁)² + τ₀ + τ₁ + τ₂ with each
    /// surface's terms taken from a model holding only that surface, the eq. 11 phases of both
    /// surfaces attain it, and no random phase draw of the concatenated vector beats it.
    #[test]
    fn two_surfaces_add_exactly_and_their_closed_form_is_the_best() {
        for grouping in [Grouping::Coherent, Grouping::Elements] {
            let two = Scenario::small_test_two_surfaces(grouping);
            let model = ChannelModel::new(&two);
            let alone: Vec<ChannelModel> = two
                .surfaces()
                .iter()
                .map(|irs| ChannelModel::new(&two.with_surfaces(vec![irs.clone()]).unwrap()))
                .collect();
            let none = ChannelModel::new(&two.with_surfaces(Vec::new()).unwrap());
            let mut rng = rand::rngs::StdRng::seed_from_u64(5);
            let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
            let mut theta = vec![0.0; w.len()];
            let mut best_random = 0.0f64;
            for _ in 0..40 {
                let q = [rng.random_range(0.2..5.8), rng.random_range(0.2..3.8), 1.0];
                let best = best_gain(&model, q, PhaseMode::Continuous, &mut w, &mut theta);
                let d0 = none.evaluate(q, false, &mut []);
                let (mut amplitude, mut tau) = (d0.h.norm(), d0.tau);
                for m in &alone {
                    let mut ws = vec![C64::new(0.0, 0.0); m.subsurfaces()];
                    let d = m.evaluate(q, true, &mut ws);
                    amplitude += l1_norm(&ws);
                    tau += d.tau - d0.tau;
                }
                let expected = amplitude.powi(2) + tau;
                assert!(
                    (best / expected - 1.0).abs() < 1e-12,
                    "{grouping:?} at {q:?}"
                );
                let d = model.evaluate(q, true, &mut w);
                model.optimal_phases(q, &mut theta);
                assert!((expected_gain(&d, &w, &theta) / best - 1.0).abs() < 1e-12);
                for _ in 0..500 {
                    let random: Vec<f64> =
                        (0..w.len()).map(|_| rng.random::<f64>() * TAU).collect();
                    let g = expected_gain(&d, &w, &random);
                    assert!(g <= best * (1.0 + 1e-12));
                    best_random = best_random.max(g / best);
                }
            }
            assert!(best_random > 0.9, "random draws come close: {best_random}");
        }
    }

    #[test]
    fn quantised_phases_never_beat_continuous_and_none_is_the_direct_link() {
        let s = Scenario::builtin("small-test").unwrap();
        let progress = Progress::default();
        let cont = build(
            &s,
            &gain_key(&s, PhaseMode::Continuous),
            "test".into(),
            &progress,
        )
        .unwrap();
        let none = build(&s, &gain_key(&s, PhaseMode::None), "test".into(), &progress).unwrap();
        let model = ChannelModel::new(&s);
        for b in 1..=3 {
            let q = build(
                &s,
                &gain_key(&s, PhaseMode::Bits(b)),
                "test".into(),
                &progress,
            )
            .unwrap();
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
        let r = build(
            &s,
            &gain_key(&s, PhaseMode::Continuous),
            "test".into(),
            &progress,
        );
        assert_eq!(r.unwrap_err(), Cancelled);
    }
}
