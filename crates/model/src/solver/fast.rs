//! The `fast` rate solver (docs/model.md §5).
//!
//! The objective depends on θ only through the K+1 numbers a_lᵀv (v = [θ; 1]). For K = 1, a
//! stationary point of any weighted sum μ_m|a_mᵀv|² + μ_s|a_sᵀv|² — and the optimum of the rate,
//! including on the SIC boundary where the Lagrangian is such a sum with real, possibly negative,
//! weights — satisfies, element by element, v_n ∥ μ_m conj(a_mn)(a_mᵀv) + μ_s conj(a_sn)(a_sᵀv).
//! So it lies in the one-complex-parameter family
//!
//! v_n(z) = exp(j∠(conj(a_mn) + z·conj(a_sn))), scaled so that v_{N+1} = 1,
//!
//! plus its limit z → ∞. We evaluate the true objective on a log-polar grid of z, refine the best
//! z by pattern search, then polish with element-wise coordinate ascent on the true objective.
//! Each element's λ_l is a sinusoid in its phase, λ_l(φ) = |b_l|² + |a_ln|² + τ_l +
//! 2 Re(conj(b_l) a_ln e^{jφ}) (b_l the sum without the element), so the score is exactly a
//! sinusoid where one user's λ alone moves it, and close to one otherwise: the ascent fits one
//! through three samples and jumps to its peak in closed form ([`sinusoid_peak`]), then fits
//! once more around that point at a finer spacing.
//!
//! For K > 1 the family has K complex parameters; rather than a K-dimensional grid we search
//! the one-parameter family of every (MRU, SRU k) pair — the directions in which the SRUs pull
//! apart — and polish the best two starts by the same coordinate ascent on the full objective.
//! Either way the certificate ([`super::certificate`]) reports how far from optimal the result can be.
//!
//! Neighbouring cells of a map have nearly the same optimal *weighting* z of each pair
//! (their phases differ completely: cells are several wavelengths apart), so a map starts each
//! pair's pattern search from the previous cell's z ([`FamilyPoint`]) instead of the 400-point
//! grid, and ascends from the best start alone; [`super::solve_cell_warm`] keeps the answer only
//! when the certificate vouches for it ([`super::WARM_START_ACCEPT_GAP`] with one SRU,
//! [`super::WARM_START_PROVEN_GAP`] with more), and otherwise runs the cold search too.
//!
//! The searches compare the rate's monotone *score* 1 + SINR ([`RateModel::mru_score`]) and take
//! one logarithm at the end.

use super::{CellProblem, score};
use crate::channel::C64;
use crate::numerics::l1_norm;
use crate::rate::RateModel;
use std::f64::consts::TAU;

/// Log10 span of |z| around the balancing scale ‖a_m‖₁/‖a_s‖₁: ±3 decades covers every
/// weighting between one user's term dominating by 60 dB and the other's.
const Z_DECADES: f64 = 3.0;
/// |z| grid points over those 6 decades (4 per decade): the pattern search that follows
/// only needs the right basin.
const Z_MAGNITUDES: usize = 25;
/// arg z grid points (22.5° apart), for the same reason.
const Z_ANGLES: usize = 16;
/// Grid points scored together by [`Evaluator::family_scores`]. The lanes share each pass over
/// the elements, so the sums of the K + 1 users in every lane overlap instead of each waiting
/// on its own additions, and square roots and divisions go two lanes an instruction. A divisor
/// of [`Z_ANGLES`], so that a magnitude's angles fill whole batches.
const LANES: usize = 4;
const _: () = assert!(Z_ANGLES.is_multiple_of(LANES));
/// Pattern-search rounds refining z (each tries the 4 neighbours and halves the steps when none
/// is better): the kept value of the cold search before warm starts, under which the step ends
/// at 1/4096 of the grid's at most, far below what moves the rate after the ascent.
const PATTERN_STEPS: usize = 12;
/// Phase grid per element in the first coordinate-ascent sweep (22.5° apart): the per-element
/// objective is a sinusoid-like curve with one maximum, which a 16-point grid brackets.
const ELEMENT_GRID: usize = 16;
/// Sweeps that scan the element's grid before fitting; later sweeps fit from the element's
/// current phase alone. After one sweep every element sits within a fraction of a grid step of
/// its maximum, so the grid only re-finds the basin it is in (measured on the paper's map: the
/// same rates to ≤ 1e-9 bit/s/Hz with the grid in every sweep, at 2.4× the evaluations).
const GRID_SWEEPS: usize = 1;
/// Spacing of the second sinusoid fit (rad). The first fit, at the grid's spacing, lands within
/// ~1e-2 rad of the peak of a score that is not exactly a sinusoid; samples ±0.05 rad around
/// that point resolve the rest while the differences stay ~1e-3 of the element's swing, far
/// above rounding.
const FINE_SPACING: f64 = 0.05;
/// Coordinate-ascent sweeps over all elements; measured to converge within 3–4 on the paper
/// scenarios, the rest is a safety margin (the loop stops early once a sweep gains < 1e-10).
const MAX_SWEEPS: usize = 6;

/// Where a (MRU, SRU) pair's family search ended: z = scale · 10^log_mag · e^{j·angle}, with
/// `log_mag` = −∞ for z = 0. What a map hands from one cell to the next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FamilyPoint {
    log_mag: f64,
    angle: f64,
}

/// Returns v = [e^{jθ}; 1] maximising the MRU's rate (continuous phases).
pub fn solve(problem: &CellProblem, model: &RateModel) -> Vec<C64> {
    solve_from(problem, model, &[]).0
}

/// [`solve`], warm-started from a neighbouring cell's family points when `hint` holds one for
/// every (MRU, SRU) pair: each pair's pattern search starts at its point (no grid) and only the
/// best start is ascended. Any other `hint` (none, or one of another scenario's length) means
/// the cold search. Returns v and each pair's family point, to hand to the next cell.
pub fn solve_from(
    problem: &CellProblem,
    model: &RateModel,
    hint: &[FamilyPoint],
) -> (Vec<C64>, Vec<FamilyPoint>) {
    let mut eval = Evaluator::new(problem, model);
    let grid = PhaseGrid::new();
    let pairs = problem.users() - 1;
    let warm = hint.len() == pairs;
    let mut starts: Vec<(f64, Vec<C64>)> = Vec::new();
    let mut points = Vec::with_capacity(pairs);
    for k in 1..=pairs {
        let (value, v, point) = search_pair(&mut eval, problem, k, warm.then(|| hint[k - 1]));
        points.push(point);
        starts.push((value, v));
    }
    // A warm start is the neighbour's basin: its pattern search's answer is the one ascended.
    if warm && pairs == 1 {
        let mut v = starts.pop().map(|(_, v)| v).unwrap_or_default();
        coordinate_ascent(&mut eval, &grid, problem, &mut v);
        return (v, points);
    }
    // The MRU's own optimum (z = 0) is in every pair's family; add each SRU's own (z → ∞).
    for k in 1..=pairs {
        let mut v = vec![C64::new(0.0, 0.0); problem.dim];
        family(problem, 0, k, None, &mut v);
        starts.push((eval.value(&v), v));
    }
    starts.sort_by(|a, b| b.0.total_cmp(&a.0));
    // Cold, the grids may rank a start first whose basin is not the best: two are ascended.
    starts.truncate(if warm { 1 } else { 2 });
    let mut best = (f64::NEG_INFINITY, starts[0].1.clone());
    for (_, mut v) in starts {
        let value = coordinate_ascent(&mut eval, &grid, problem, &mut v);
        if value > best.0 {
            best = (value, v);
        }
    }
    (best.1, points)
}

/// Element-wise coordinate ascent on the true objective from `v` (continuous phases), as the
/// searches end: what a start from elsewhere (the certificate's dual) is polished with.
pub fn polish(problem: &CellProblem, model: &RateModel, v: &mut [C64]) {
    let mut eval = Evaluator::new(problem, model);
    coordinate_ascent(&mut eval, &PhaseGrid::new(), problem, v);
}

/// The coordinate ascent's fixed rotations, computed once per solve rather than once per
/// element and sweep: the grid phasors e^{j2πg/16} and the fits' sample offsets.
struct PhaseGrid {
    phasors: [C64; ELEMENT_GRID],
    coarse: Spacing,
    fine: Spacing,
}

/// A fit's sample spacing h with e^{jh}, sin h and cos h − 1.
struct Spacing {
    h: f64,
    rotation: C64,
    sin: f64,
    cos_minus_one: f64,
}

impl Spacing {
    fn new(h: f64) -> Spacing {
        Spacing {
            h,
            rotation: C64::from_polar(1.0, h),
            sin: h.sin(),
            cos_minus_one: h.cos() - 1.0,
        }
    }
}

impl PhaseGrid {
    fn new() -> PhaseGrid {
        PhaseGrid {
            phasors: std::array::from_fn(|g| {
                C64::from_polar(1.0, TAU * g as f64 / ELEMENT_GRID as f64)
            }),
            coarse: Spacing::new(TAU / ELEMENT_GRID as f64),
            fine: Spacing::new(FINE_SPACING),
        }
    }
}

/// The offset t ∈ [−h, h] of the peak of the sinusoid f(t) = A + u cos t − w sin t through the
/// samples (−h, f₋), (0, f₀), (h, f₊): u = (f₊ + f₋ − 2f₀)/(2(cos h − 1)),
/// w = (f₋ − f₊)/(2 sin h), peak at t = atan2(−w, u) (where f = A + √(u² + w²)). Exact for a
/// sinusoid; clamped to the samples' span, since beyond it the fit is an extrapolation. `None`
/// when a sample is −∞ (an SRU cannot be served there).
fn sinusoid_peak(f_minus: f64, f0: f64, f_plus: f64, spacing: &Spacing) -> Option<f64> {
    if !(f_minus.is_finite() && f0.is_finite() && f_plus.is_finite()) {
        return None;
    }
    let u = (f_plus + f_minus - 2.0 * f0) / (2.0 * spacing.cos_minus_one);
    let w = (f_minus - f_plus) / (2.0 * spacing.sin);
    let t = (-w).atan2(u);
    t.is_finite().then(|| t.clamp(-spacing.h, spacing.h))
}

/// v_n(z) for the pair (MRU = user `m`, SRU `k`); `z = None` is the limit z → ∞.
fn family(problem: &CellProblem, m: usize, k: usize, z: Option<C64>, v: &mut [C64]) {
    let (am, ak) = (problem.user(m), problem.user(k));
    for n in 0..problem.dim {
        let c = match z {
            Some(z) => am[n].conj() + z * ak[n].conj(),
            None => ak[n].conj(),
        };
        // |c| without hypot's overflow care (a third of a map's time): channel coefficients
        // are far from both ends of f64's range.
        let r = c.norm_sqr().sqrt();
        v[n] = if r > 0.0 && r.is_finite() {
            c / r
        } else {
            C64::new(1.0, 0.0)
        };
    }
    let reference = v[problem.dim - 1].conj();
    v.iter_mut().for_each(|x| *x *= reference);
}

/// Grid search (or a neighbour's `hint`) and pattern-search refinement of z for one
/// (MRU, SRU) pair; returns the best score, its v and where it is.
fn search_pair(
    eval: &mut Evaluator,
    problem: &CellProblem,
    k: usize,
    hint: Option<FamilyPoint>,
) -> (f64, Vec<C64>, FamilyPoint) {
    let l1 = |l: usize| l1_norm(problem.user(l));
    // Balance the two users' terms; if either has no IRS term the family does not depend on the
    // scale, and a degenerate one (0 or ∞) would push z into subnormal arithmetic.
    let scale = match (l1(0), l1(k)) {
        (m, s) if m > 0.0 && s > 0.0 => m / s,
        _ => 1.0,
    };
    let mut v = vec![C64::new(0.0, 0.0); problem.dim];
    let at = |eval: &mut Evaluator, log_mag: f64, angle: f64, v: &mut Vec<C64>| {
        family(
            problem,
            0,
            k,
            Some(C64::from_polar(scale * 10f64.powf(log_mag), angle)),
            v,
        );
        eval.value(v)
    };
    let grid_step_mag = 2.0 * Z_DECADES / (Z_MAGNITUDES - 1) as f64;
    let grid_step_angle = TAU / Z_ANGLES as f64;
    let zero = FamilyPoint {
        log_mag: f64::NEG_INFINITY,
        angle: 0.0,
    };
    // z = 0 (the MRU's own optimum, eq. 11's analogue) always competes.
    let at_zero = at(eval, zero.log_mag, zero.angle, &mut v);
    let (mut best, mut step_mag, mut step_angle) = match hint {
        // A neighbour's point is near this cell's: a quarter of the grid's steps.
        Some(h) if h.log_mag.is_finite() => (
            (at(eval, h.log_mag, h.angle, &mut v), h.log_mag, h.angle),
            grid_step_mag / 4.0,
            grid_step_angle / 4.0,
        ),
        // The neighbour's optimum was z = 0: so, likely, is this one's.
        Some(_) => (
            (f64::NEG_INFINITY, 0.0, 0.0),
            grid_step_mag,
            grid_step_angle,
        ),
        None => {
            let mut best = (f64::NEG_INFINITY, -Z_DECADES - 1.0, 0.0);
            for mi in 0..Z_MAGNITUDES {
                let log_mag = -Z_DECADES + grid_step_mag * mi as f64;
                let magnitude = scale * 10f64.powf(log_mag);
                for first in (0..Z_ANGLES).step_by(LANES) {
                    let angle = |j: usize| grid_step_angle * (first + j) as f64;
                    let values = eval.family_scores(
                        k,
                        std::array::from_fn(|j| C64::from_polar(magnitude, angle(j))),
                    );
                    // In grid order, so that ties go to the first point as one by one.
                    for (j, value) in values.into_iter().enumerate() {
                        if value > best.0 {
                            best = (value, log_mag, angle(j));
                        }
                    }
                }
            }
            (best, grid_step_mag, grid_step_angle)
        }
    };
    if at_zero >= best.0 || !best.0.is_finite() {
        at(eval, zero.log_mag, zero.angle, &mut v);
        return (at_zero, v, zero);
    }
    for _ in 0..PATTERN_STEPS {
        let mut moved = false;
        for (dm, da) in [
            (step_mag, 0.0),
            (-step_mag, 0.0),
            (0.0, step_angle),
            (0.0, -step_angle),
        ] {
            let value = at(eval, best.1 + dm, best.2 + da, &mut v);
            if value > best.0 {
                best = (value, best.1 + dm, best.2 + da);
                moved = true;
            }
        }
        if !moved {
            step_mag /= 2.0;
            step_angle /= 2.0;
        }
    }
    let value = at(eval, best.1, best.2, &mut v);
    let point = FamilyPoint {
        log_mag: best.1,
        angle: best.2.rem_euclid(TAU),
    };
    (value, v, point)
}

/// Reusable buffers for evaluating the objective without allocating.
struct Evaluator<'a> {
    model: &'a RateModel,
    problem: &'a CellProblem,
    lambdas: Vec<f64>,
    sums: Vec<C64>,
    base: Vec<C64>,
    /// [`Self::family_scores`]'s v, element by element, a lane per z (real and imaginary parts).
    lane_v: Vec<[[f64; LANES]; 2]>,
    /// [`Self::family_scores`]'s a_lᵀv per user, a lane per z.
    lane_sums: Vec<[[f64; LANES]; 2]>,
}

impl<'a> Evaluator<'a> {
    fn new(problem: &'a CellProblem, model: &'a RateModel) -> Self {
        let users = problem.users();
        Evaluator {
            model,
            problem,
            lambdas: vec![0.0; users],
            sums: vec![C64::new(0.0, 0.0); users],
            base: vec![C64::new(0.0, 0.0); users],
            lane_v: vec![[[0.0; LANES]; 2]; problem.dim],
            lane_sums: vec![[[0.0; LANES]; 2]; users],
        }
    }

    /// The scores at v = `family(problem, 0, k, Some(z))` for [`LANES`] values of z at once.
    /// Each lane does [`family`]'s and [`Self::value`]'s arithmetic (num-complex's formulas,
    /// the sums in element order from zero), so its score is theirs bit for bit (tested): the
    /// lanes only share the loops, which is what lets the compiler run them side by side.
    fn family_scores(&mut self, k: usize, zs: [C64; LANES]) -> [f64; LANES] {
        let problem = self.problem;
        let (am, ak) = (problem.user(0), problem.user(k));
        let (z_re, z_im) = (zs.map(|z| z.re), zs.map(|z| z.im));
        for ((v, &m), &s) in self.lane_v.iter_mut().zip(am).zip(ak) {
            let (a, b) = (m.conj(), s.conj());
            let [v_re, v_im] = v;
            for j in 0..LANES {
                // c = conj(a_mn) + z·conj(a_kn), normalised.
                let c_re = a.re + (z_re[j] * b.re - z_im[j] * b.im);
                let c_im = a.im + (z_re[j] * b.im + z_im[j] * b.re);
                let r = (c_re * c_re + c_im * c_im).sqrt();
                // Choosing the operands rather than the quotients keeps the lanes branch-free
                // (1/1 and 0/1 are exact).
                let (c_re, c_im, r) = if r > 0.0 && r.is_finite() {
                    (c_re, c_im, r)
                } else {
                    (1.0, 0.0, 1.0)
                };
                v_re[j] = c_re / r;
                v_im[j] = c_im / r;
            }
        }
        // v ← v · conj(v_{N+1}), as `*=` multiplies.
        let [last_re, last_im] = self.lane_v[problem.dim - 1];
        for [v_re, v_im] in self.lane_v.iter_mut() {
            for j in 0..LANES {
                let (x, y) = (v_re[j], v_im[j]);
                v_re[j] = x * last_re[j] - y * -last_im[j];
                v_im[j] = y * last_re[j] + x * -last_im[j];
            }
        }
        // A user at a time, its lanes' sums in registers.
        for (l, sums) in self.lane_sums.iter_mut().enumerate() {
            let [mut s_re, mut s_im] = [[0.0; LANES]; 2];
            for (a, [v_re, v_im]) in problem.user(l).iter().zip(&self.lane_v) {
                for j in 0..LANES {
                    s_re[j] += a.re * v_re[j] - a.im * v_im[j];
                    s_im[j] += a.re * v_im[j] + a.im * v_re[j];
                }
            }
            *sums = [s_re, s_im];
        }
        std::array::from_fn(|j| {
            for (l, [s_re, s_im]) in self.lane_sums.iter().enumerate() {
                self.lambdas[l] = s_re[j] * s_re[j] + s_im[j] * s_im[j] + problem.tau[l];
            }
            score(self.model, &self.lambdas)
        })
    }

    /// The score (1 + the MRU's SINR, monotone in its rate) at v; −∞ where an SRU cannot be
    /// served.
    fn value(&mut self, v: &[C64]) -> f64 {
        self.problem.lambdas(v, &mut self.lambdas);
        score(self.model, &self.lambdas)
    }

    /// The score with element n set to e^{jφ}, given `base_l = a_lᵀv − a_ln v_n` in `self.base`.
    #[inline]
    fn value_with(&mut self, n: usize, phasor: C64) -> f64 {
        for l in 0..self.problem.users() {
            let s = self.base[l] + self.problem.user(l)[n] * phasor;
            self.lambdas[l] = s.norm_sqr() + self.problem.tau[l];
        }
        score(self.model, &self.lambdas)
    }

    fn load_sums(&mut self, v: &[C64]) {
        for l in 0..self.problem.users() {
            self.sums[l] = self.problem.user(l).iter().zip(v).map(|(a, x)| a * x).sum();
        }
    }

    fn exclude(&mut self, n: usize, vn: C64) {
        for l in 0..self.problem.users() {
            self.base[l] = self.sums[l] - self.problem.user(l)[n] * vn;
        }
    }

    fn include(&mut self, n: usize, vn: C64) {
        for l in 0..self.problem.users() {
            self.sums[l] = self.base[l] + self.problem.user(l)[n] * vn;
        }
    }
}

/// Element-wise coordinate ascent on the true objective (continuous phases). Returns the score.
fn coordinate_ascent(
    eval: &mut Evaluator,
    grid: &PhaseGrid,
    problem: &CellProblem,
    v: &mut [C64],
) -> f64 {
    eval.load_sums(v);
    let mut current = eval.value(v);
    for sweep in 0..MAX_SWEEPS {
        let before = current;
        for (n, vn) in v[..problem.dim - 1].iter_mut().enumerate() {
            eval.exclude(n, *vn);
            let (value, phasor) =
                maximise_element(eval, grid, n, current, *vn, sweep < GRID_SWEEPS);
            if value > current {
                // Products of unit phasors drift from |v_n| = 1 by rounding; renormalise.
                *vn = phasor / phasor.norm();
                current = value;
            }
            eval.include(n, *vn);
        }
        // Scores are ≥ 1 where finite: a relative test.
        if current - before <= 1e-10 * current.abs().max(1.0) {
            break;
        }
    }
    current
}

/// The best (score, phasor) found for element n, starting from its phasor `vn` and score
/// `current` (`eval.base` holds the sums without it): with `scan`, the grid's best point and its
/// two neighbours seed the first sinusoid fit; without, the current phase ± one grid step do.
/// A second fit at [`FINE_SPACING`] around the best point so far finishes. Never worse than
/// `current`.
fn maximise_element(
    eval: &mut Evaluator,
    grid: &PhaseGrid,
    n: usize,
    current: f64,
    vn: C64,
    scan: bool,
) -> (f64, C64) {
    let mut best = (current, vn);
    let consider = |value: f64, phasor: C64, best: &mut (f64, C64)| {
        if value > best.0 {
            *best = (value, phasor);
        }
    };
    let coarse = &grid.coarse;
    let (centre, f0, f_minus, f_plus) = if scan {
        let mut values = [0.0; ELEMENT_GRID];
        for (value, &phasor) in values.iter_mut().zip(&grid.phasors) {
            *value = eval.value_with(n, phasor);
        }
        let g = (0..ELEMENT_GRID)
            .max_by(|&a, &b| values[a].total_cmp(&values[b]))
            .unwrap_or(0);
        consider(values[g], grid.phasors[g], &mut best);
        let at = |offset: usize| values[(g + offset) % ELEMENT_GRID];
        (grid.phasors[g], values[g], at(ELEMENT_GRID - 1), at(1))
    } else {
        let minus = vn * coarse.rotation.conj();
        let plus = vn * coarse.rotation;
        let (f_minus, f_plus) = (eval.value_with(n, minus), eval.value_with(n, plus));
        consider(f_minus, minus, &mut best);
        consider(f_plus, plus, &mut best);
        (vn, current, f_minus, f_plus)
    };
    if let Some(t) = sinusoid_peak(f_minus, f0, f_plus, coarse) {
        let phasor = centre * C64::from_polar(1.0, t);
        consider(eval.value_with(n, phasor), phasor, &mut best);
    }
    let fine = &grid.fine;
    let (centre, f0) = (best.1, best.0);
    let minus = centre * fine.rotation.conj();
    let plus = centre * fine.rotation;
    let (f_minus, f_plus) = (eval.value_with(n, minus), eval.value_with(n, plus));
    consider(f_minus, minus, &mut best);
    consider(f_plus, plus, &mut best);
    if let Some(t) = sinusoid_peak(f_minus, f0, f_plus, fine) {
        let phasor = centre * C64::from_polar(1.0, t);
        consider(eval.value_with(n, phasor), phasor, &mut best);
    }
    best
}

/// Discrete phases (`bits: b`): project v onto the L = 2^b levels, then re-optimise element by
/// element over the levels (all of them for L ≤ 64, else the 64 nearest the current phase) until
/// no element improves.
pub fn discrete_ascent(problem: &CellProblem, model: &RateModel, bits: u8, v: &mut [C64]) {
    let levels = 1usize << bits;
    let step = TAU / levels as f64;
    let level_of = |x: C64| ((x.arg().rem_euclid(TAU) / step).round() as usize) % levels;
    let phasor = |level: usize| C64::from_polar(1.0, level as f64 * step);
    for x in v[..problem.dim - 1].iter_mut() {
        *x = phasor(level_of(*x));
    }
    let mut eval = Evaluator::new(problem, model);
    eval.load_sums(v);
    let mut current = eval.value(v);
    let window = levels.min(64);
    for _ in 0..4 * MAX_SWEEPS {
        let mut improved = false;
        for (n, vn) in v[..problem.dim - 1].iter_mut().enumerate() {
            eval.exclude(n, *vn);
            let here = level_of(*vn);
            for offset in 0..window {
                let level = (here + levels + offset - window / 2) % levels;
                let value = eval.value_with(n, phasor(level));
                if value > current + 1e-12 * current.abs().max(1.0) {
                    current = value;
                    *vn = phasor(level);
                    improved = true;
                }
            }
            eval.include(n, *vn);
        }
        if !improved {
            break;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rate::Access;
    use proptest::prelude::*;

    /// A cell problem of `users` users and `dim` elements from `seed`: magnitudes over eight
    /// decades, some coefficients exactly zero (where family's normalisation falls back to 1).
    fn problem(users: usize, dim: usize, seed: u64) -> CellProblem {
        let mut state = seed | 1;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let a = (0..users * dim)
            .map(|_| {
                if next() < 0.05 {
                    C64::new(0.0, 0.0)
                } else {
                    C64::from_polar(10f64.powf(-8.0 * next()), TAU * next())
                }
            })
            .collect();
        let tau = (0..users).map(|_| 1e-9 * next()).collect();
        CellProblem { dim, a, tau }
    }

    proptest! {
        /// The batch of grid points scores each z exactly as `family` then `value` do one at
        /// a time, for every pair, under NOMA and OMA, with z from 0 to beyond f64's range.
        #[test]
        fn a_batch_of_family_points_scores_each_as_one_alone(
            users in 2usize..=5,
            dim in 1usize..=64,
            seed in any::<u64>(),
            log_mags in proptest::array::uniform4(-320.0f64..320.0),
            angles in proptest::array::uniform4(0.0f64..TAU),
            oma in any::<bool>(),
        ) {
            let problem = problem(users, dim, seed);
            let access = if oma { Access::Oma } else { Access::Noma };
            let targets = vec![0.01; users - 1];
            // Noise far below the weakest gain (1e-16): every SRU is served, scores are finite.
            let model = RateModel::new(access, 1e-3, 1e-23, &targets);
            let mut eval = Evaluator::new(&problem, &model);
            let mut zs: [C64; LANES] =
                std::array::from_fn(|j| C64::from_polar(10f64.powf(log_mags[j]), angles[j]));
            zs[0] = C64::new(0.0, 0.0);
            let mut v = vec![C64::new(0.0, 0.0); dim];
            for k in 1..users {
                let batch = eval.family_scores(k, zs);
                for (z, score) in zs.into_iter().zip(batch) {
                    family(&problem, 0, k, Some(z), &mut v);
                    let alone = eval.value(&v);
                    prop_assert!(score.is_finite());
                    prop_assert_eq!(score.to_bits(), alone.to_bits(), "k {}, z {}", k, z);
                }
            }
        }
    }
}
