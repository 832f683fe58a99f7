//! An upper bound on the MRU's rate from the semidefinite relaxation (SDR), without an SDP
//! solver (docs/model.md §5).
//!
//! Relax v vᴴ to V ⪰ 0 with diag V = 1 (paper problem 29 without the rank constraint, eq. 29g).
//! For K = 1 the relaxed gains (x, y) = (tr(A V), tr(B V)), A = ā āᴴ and B = b̄ b̄ᴴ (a, b the MRU's
//! and SRU's a-vectors), fill a convex set S ⊂ R²₊. Its support function in a direction
//! w = (w₁, w₂) ≥ 0 is the SDP h(w) = max{tr(W V) : V ⪰ 0, diag V = 1} with the rank-2
//! W = U Uᴴ, U = [√w₁ ā, √w₂ b̄]. By SDP duality (dual variable Diag(y) ⪰ W, Schur complement with
//! z = 1/y):
//!
//! h(w) = min{ Σ 1/z_n : Σ z_n ρ_n ρ_nᴴ ⪯ I₂ }  (ρ_n = (√w₁ a_n, √w₂ b_n)ᵀ)
//!      = max_{Λ ⪰ 0, tr Λ = 1} ( Σ_n √(ρ_nᴴ Λ ρ_n) )².
//!
//! Writing Λ = (I + x·σ)/2 with x in the unit ball (σ the Pauli matrices) makes the inner sum a
//! concave function of x ∈ R³, maximised here by Newton steps that keep the ball exactly
//! (each maximises the quadratic model over the ball: a trust-region subproblem). Any Λ
//! gives z_n = 1/√(ρ_nᴴ Λ ρ_n); scaling z by λ_max(Σ z_n ρ_n ρ_nᴴ) makes it feasible, so
//! λ_max · Σ 1/z_n is a *valid* upper bound on h(w) however inexact the maximisation.
//!
//! The bounds h̄(w) for a set of directions define an outer polygon of S. Shifted by (τ_m, τ_s)
//! and intersected with each decoding order's SIC half-plane and the SRU's feasibility
//! half-plane, it contains every relaxed (λ_m, λ_s); the MRU rate is quasi-concave in the gains
//! (see [`crate::rate`]), so its maximum over each polygon edge is found by golden-section
//! search. Directions are refined adaptively around the maximiser.
//!
//! For K ≥ 2 the relaxed gains live in R^{K+1} and a polytope would need many directions; the
//! bound is instead the relaxation's Lagrange dual, per decoding order ([`joint_bound`]):
//! - Score x (2^r) is reachable under an order at gains λ iff Σ_l c_l(x)/λ_l ≤ P_max
//!   ([`RateModel::power_costs`]), a convex function of λ.
//! - For any w ≥ 0, every relaxed λ has w·λ ≤ h(w) + w·τ, with h the support function above
//!   for K + 1 users: the same duality with a (K+1) × (K+1) multiplier Λ ([`joint_support`]).
//! - On the order's region λ_{π[0]} ≤ … ≤ λ_{π[K]}, multipliers μ ≥ 0 give g·λ ≤ w·λ for
//!   g = w + Dᵀμ ([`ordered_weights`] picks the best μ for a w).
//! - On a half-space g·λ ≤ B the least Σ c_l/λ_l is (Σ_l √(c_l g_l))²/B (Cauchy–Schwarz), so
//!   the order's score is at most the root of (Σ_l √(c_l(x) g_l))² = P_max·B
//!   ([`RateModel::score_bound`]).
//!
//! Every (w, μ) gives a valid bound (weak duality); the best one is the relaxation's own value
//! (strong duality: the relaxed problem is convex and strictly feasible wherever it is
//! feasible). The direction is searched by a multiplicative ascent from the primal's gains, the
//! primal's order first; other orders only where their cheap box bound (each user at most its
//! own maximum and the ordering's caps) beats the best so far, and each only until it falls
//! below it. The dual of the top order also rounds to phases ([`Certified::lead`]), which the
//! `fast` solver polishes where they beat its own: that is how a missed decoding order is found.

use super::CellProblem;
use crate::channel::C64;
use crate::numerics::{golden_section_max, l1_norm};
use crate::rate::{Access, RateModel};
use crate::scenario::MAX_SRUS;
use nalgebra::{Matrix3, Vector3};
use std::f64::consts::FRAC_PI_2;

/// Directions of the first outer polygon, evenly spread over [0, π/2]. Measured on the paper's
/// NOMA map at equal speed: 5 directions gave a max gap of 0.016 bit/s/Hz, 7 give 0.0022.
const INITIAL_DIRECTIONS: usize = 7;
/// Adaptive refinement rounds (each bisects the angles next to the active edge); the loop
/// usually stops earlier on [`REFINEMENT_SETTLED`].
const REFINEMENT_ROUNDS: usize = 5;
/// A refinement round that lowers the rate bound by less than this (bit/s/Hz) ends refinement:
/// 100× below the gaps worth reporting, and it halved the certificate's time on the paper map.
const REFINEMENT_SETTLED: f64 = 1e-6;
/// Relative duality gap at which the support-function maximisation stops: the bound is valid
/// at any gap. Newton converges quadratically, so 1e-9 costs little over 1e-6 (1.8 against 1.35
/// steps per direction on the paper's NOMA map) and keeps the median cell gap where the
/// barrier method had it (2.8e-7 bit/s/Hz; 3.3e-7 at 1e-6).
const GAP_TOLERANCE: f64 = 1e-9;
/// Newton steps of the support-function maximisation; it converges quadratically and closes
/// [`GAP_TOLERANCE`] in a handful (measured on the paper's NOMA map: 1.8 steps per direction
/// on average, warm-started from the neighbouring direction; the barrier method this replaced
/// took 47.5 steps of 8.7 line-search trials each).
const MAX_NEWTON_STEPS: usize = 30;
/// Step halvings before a Newton step is given up as lost in rounding (2^-30 of the step).
const LINE_SEARCH_HALVINGS: usize = 30;
/// Newton/bisection steps on the secular equation of [`ball_newton_point`]: Newton converges
/// in a few from either side; the cap only matters when bisection takes over.
const SECULAR_STEPS: usize = 60;
/// |‖y‖ − 1| at which the model's maximiser on the sphere is taken (rescaled onto it): the step
/// is a model's anyway, so this only needs to keep y in the ball.
const SECULAR_TOLERANCE: f64 = 1e-12;
/// Users a cell can have: the MRU and up to [`MAX_SRUS`] SRUs (fixed-size arrays on the stack).
const MOST_USERS: usize = MAX_SRUS + 1;
/// M of [`joint_support`], sized for the most users (the top-left n × n block is used).
type Matrix5 = nalgebra::Matrix5<C64>;
/// Power-iteration steps of [`joint_support`] (each O(N (K+1)²)); it stops earlier once the
/// bound meets the lower estimate to [`JOINT_TOLERANCE`].
const JOINT_STEPS: usize = 200;
/// Relative agreement of [`joint_support`]'s bound and lower estimate at which it stops.
const JOINT_TOLERANCE: f64 = 1e-9;
/// Rounds of the direction fixed point per order in [`order_score_bound`].
const DIRECTION_ROUNDS: usize = 30;
/// The exponent of [`order_score_bound`]'s multiplicative direction step at its largest (2 is
/// the fixed point w ← c/(s + τ)², which overshoots)...
const DIRECTION_STEP: f64 = 1.0;
/// ...and at its smallest, below which the search has converged.
const DIRECTION_STEP_MIN: f64 = 1e-3;
/// Relative score excess over the primal's at which an order's dual search stops: 1e-9 of the
/// score is about 1.4e-9 bit/s/Hz.
const PRIMAL_SETTLED: f64 = 1e-9;
/// The identity's share in the dual's rank-one start ([`seed_dual`]).
const SEED_IDENTITY: f64 = 1e-2;
/// Smallest weight of a user in a direction (relative to a sum of 1): keeps ∂h/∂w_l finite.
const WEIGHT_FLOOR: f64 = 1e-12;
/// Smallest gain of a projected point, relative to the user's maximum: keeps c_l/λ_l² finite.
const GAIN_FLOOR: f64 = 1e-9;
/// Smallest score excess over 1 that directions are computed at (the MRU's cost vanishes at
/// rate 0 and would drop it from the direction).
const SCORE_FLOOR: f64 = 1e-9;
/// Golden-section steps per polygon edge: 0.618^60 ≈ 3e-13 of the edge, i.e. to rounding.
const EDGE_SEARCH_STEPS: usize = 60;

/// A cell's certificate.
#[derive(Debug, Clone)]
pub struct Certified {
    /// An upper bound on the MRU's rate over all phase vectors (−∞ if even the relaxation
    /// cannot serve every SRU).
    pub upper_bound: f64,
    /// K ≥ 2: phases rounded from the dual of the order with the highest bound,
    /// v_n = conj(yᴴρ_n)/|yᴴρ_n| with y the top direction of its Λ. Where that order's
    /// relaxation is tight they attain its bound (the rank-one case of [`joint_support`]'s
    /// duality), so a primal that missed the order can start there.
    pub lead: Option<Vec<C64>>,
}

/// The upper bound on the MRU's rate over all phase vectors, and a lead for the primal.
/// `hint` is a phase vector v = [e^{jθ}; 1] believed good (the primal solver's): for K ≥ 2 it
/// only steers the dual search, so any hint, or none, gives a valid bound, and a near-optimal
/// one a tight bound where the relaxation is tight. K = 1 needs none.
pub fn certify(problem: &CellProblem, model: &RateModel, hint: Option<&[C64]>) -> Certified {
    if problem.users() > MOST_USERS {
        // Scenarios have at most MAX_SRUS SRUs; beyond the stack arrays, claim nothing.
        return Certified {
            upper_bound: f64::INFINITY,
            lead: None,
        };
    }
    if problem.users() == 2 {
        Certified {
            upper_bound: polygon_bound(problem, model),
            lead: None,
        }
    } else {
        joint_bound(problem, model, hint)
    }
}

/// Whether the SRUs can be served at all, by the cheap per-user bound (`false` proves they
/// cannot, so no search is needed; `true` proves nothing).
pub fn may_serve(problem: &CellProblem, model: &RateModel) -> bool {
    if problem.users() > MOST_USERS {
        return true;
    }
    let maxima = maxima(problem);
    (0..model.orders().len()).any(|k| box_score(model, &maxima, k).is_some())
}

/// λ_l ≤ ‖a_l‖₁² + τ_l for every user (attained by the relaxation: A_l has rank one).
fn maxima(problem: &CellProblem) -> [f64; MOST_USERS] {
    let mut out = [0.0; MOST_USERS];
    for (l, o) in out.iter_mut().enumerate().take(problem.users()) {
        *o = problem.max_gain(l);
    }
    out
}

/// The MRU's best score under `order` over the box of the per-user maxima cut down by the
/// order's channel ordering (user π[t] at most the smallest maximum from position t on):
/// every order's score increases in every gain, so this bounds the order. `None` if the box's
/// top corner cannot serve every SRU.
fn box_score(model: &RateModel, maxima: &[f64; MOST_USERS], order: usize) -> Option<f64> {
    let corner = order_caps(&model.orders()[order], maxima, model.access);
    model.mru_score_ignoring_ordering(&corner[..model.users()], order)
}

/// The most each user's gain can be on an order's region: its own maximum, and under NOMA the
/// smallest maximum from its position on (the ordering puts it below every later user).
fn order_caps(pi: &[u8], maxima: &[f64; MOST_USERS], access: Access) -> [f64; MOST_USERS] {
    let mut caps = [0.0; MOST_USERS];
    let mut cap = f64::INFINITY;
    for &u in pi.iter().rev() {
        let u = u as usize;
        cap = match access {
            Access::Noma => cap.min(maxima[u]),
            Access::Oma => maxima[u],
        };
        caps[u] = cap;
    }
    caps
}

/// The K ≥ 2 bound: per decoding order, the dual of the relaxed problem (docs/model.md §5).
///
/// For gains λ in the relaxed set S + τ and a direction w ≥ 0, w·λ ≤ h(w) + w·τ, with h the
/// support function of S ([`joint_support`]); on that half-space the order's score is at most
/// [`RateModel::score_bound`]'s exact value. Any w gives a valid bound; the best is the normal
/// of S + τ at the relaxed optimum λ*, where the rate's level set touches it:
/// w ∝ ∇(Σ c_l/λ_l) = (c_l/λ_l²)_l. The search ([`order_score_bound`]) starts there from the
/// primal's gains moved into the order's region, and keeps the least bound. An order is
/// searched only if its box bound ([`box_score`]) beats the best bound so far, and the
/// primal's own order goes first.
fn joint_bound(problem: &CellProblem, model: &RateModel, hint: Option<&[C64]>) -> Certified {
    let n = problem.users();
    let maxima = maxima(problem);
    let mut amplitudes = [C64::new(0.0, 0.0); MOST_USERS];
    let mut start = maxima;
    if let Some(v) = hint {
        for l in 0..n {
            amplitudes[l] = problem.user(l).iter().zip(v).map(|(a, v)| a * v).sum();
            start[l] = amplitudes[l].norm_sqr() + problem.tau[l];
        }
    }
    let at_start = model.best_order(&start[..n]);
    let first = at_start.map(|(_, k)| k);
    let mut orders: Vec<(f64, usize)> = (0..model.orders().len())
        .filter_map(|k| box_score(model, &maxima, k).map(|cap| (cap, k)))
        .collect();
    orders.sort_by(|p, q| {
        (Some(q.1) == first)
            .cmp(&(Some(p.1) == first))
            .then(q.0.total_cmp(&p.0))
    });
    // An order bounded within PRIMAL_SETTLED of the primal's own score is as good as
    // certified: its search stops there.
    let primal = at_start
        .filter(|_| hint.is_some())
        .map_or(f64::NEG_INFINITY, |(s, _)| s);
    let mut best = f64::NEG_INFINITY;
    let mut lead = None;
    for (cap, order) in orders {
        if cap <= best {
            continue;
        }
        let (bound, dual) = order_score_bound(
            problem,
            model,
            order,
            &start,
            &amplitudes,
            &maxima,
            cap,
            best.max(primal * (1.0 + PRIMAL_SETTLED)),
        );
        if bound > best {
            best = bound;
            lead = dual;
        }
    }
    Certified {
        upper_bound: model.rate_of_score(best),
        lead: lead.map(|(y, w)| round_dual(problem, &y, &w[..n])),
    }
}

/// The phases a dual iterate points at: y the top eigenvector of Λ = Y Yᴴ, then
/// v_n = conj(yᴴρ_n)/|yᴴρ_n| (ρ_n = (√w_l a_{l,n})_l), scaled so that v_{N+1} = 1.
fn round_dual(problem: &CellProblem, y: &Square, w: &[f64]) -> Vec<C64> {
    let n = w.len();
    let lambda = nalgebra::DMatrix::from_fn(n, n, |l, k| {
        (0..n).map(|j| y[l][j] * y[k][j].conj()).sum::<C64>()
    });
    let eigen = lambda.symmetric_eigen();
    let top = eigen.eigenvalues.imax();
    let direction = eigen.eigenvectors.column(top);
    let mut v: Vec<C64> = (0..problem.dim)
        .map(|e| {
            let t: C64 = (0..n)
                .map(|l| direction[l].conj() * problem.a[l * problem.dim + e] * w[l].sqrt())
                .sum();
            if t.norm() > 0.0 {
                t.conj() / t.norm()
            } else {
                C64::new(1.0, 0.0)
            }
        })
        .collect();
    let anchor = v[problem.dim - 1].conj();
    for x in &mut v {
        *x *= anchor;
    }
    v
}

/// The joint dual bound on one order's score (at most `cap`; −∞ if the relaxation cannot serve
/// the SRUs in this order), from the gains `start`. It stops early once the bound is at most
/// `enough`: below the best bound of another order it no longer matters.
///
/// Each round takes a direction w, bounds h(w) ([`joint_support`]), gives the ordering its
/// best multipliers for that w ([`ordered_weights`]: g = w + Dᵀμ) and evaluates the exact
/// bound on the half-space. At the optimum the support point s(w) + τ equals the gains the
/// bound's minimiser implies, λ_l = √(c_l/g_l). The next direction scales each w_l by
/// (λ_l/(s_l + τ_l))^η; η = 2 would be the fixed point w ← (c_l/(s_l + τ_l)²)_l (the normal of
/// the rate's level set at the support point, without active orderings), which overshoots, so
/// η ≤ 1, quartered after a step that does not lower the bound and grown by half after one
/// that does.
#[allow(clippy::too_many_arguments)]
fn order_score_bound(
    problem: &CellProblem,
    model: &RateModel,
    order: usize,
    start: &[f64; MOST_USERS],
    amplitudes: &[C64; MOST_USERS],
    maxima: &[f64; MOST_USERS],
    cap: f64,
    enough: f64,
) -> (f64, Option<(Square, [f64; MOST_USERS])>) {
    let n = problem.users();
    let pi = &model.orders()[order];
    let mut lambda = *start;
    project_onto_order(&mut lambda[..n], pi, maxima, model.access);
    let score = model
        .mru_score_ignoring_ordering(&lambda[..n], order)
        .unwrap_or(cap)
        .min(cap);
    let mut costs = [0.0; MOST_USERS];
    model.power_costs(order, score.max(1.0 + SCORE_FLOOR), &mut costs[..n]);
    let mut w = [0.0; MOST_USERS];
    for l in 0..n {
        w[l] = costs[l] / (lambda[l] * lambda[l]);
    }
    if !normalise(&mut w[..n]) {
        return (cap, None);
    }
    let mut y = [[C64::new(0.0, 0.0); MOST_USERS]; MOST_USERS];
    seed_dual(&mut y, amplitudes, &w, n);
    // One direction's bound: (score bound or None if the order serves nobody, support point,
    // multiplied weights g).
    let evaluate = |w: &[f64; MOST_USERS], y: &mut Square, costs: &[f64; MOST_USERS]| {
        let support = joint_support(problem, &w[..n], y);
        let budget = support.bound + (0..n).map(|l| w[l] * problem.tau[l]).sum::<f64>();
        let g = ordered_weights(&w[..n], &costs[..n], pi, model.access);
        (model.score_bound(order, &g[..n], budget), support, g)
    };
    let (first, mut support, mut g) = evaluate(&w, &mut y, &costs);
    let Some(mut best) = first else {
        return (f64::NEG_INFINITY, None); // not even rate 0: this order serves nobody
    };
    best = best.min(cap);
    let mut step = DIRECTION_STEP;
    for _ in 0..DIRECTION_ROUNDS {
        if best <= enough || step < DIRECTION_STEP_MIN {
            break;
        }
        // Costs at the bound reached; the trial direction.
        model.power_costs(order, best.max(1.0 + SCORE_FLOOR), &mut costs[..n]);
        let mut trial = w;
        for l in 0..n {
            let implied = (costs[l] / g[l]).sqrt();
            let support_gain = (support.point[l] + problem.tau[l]).max(GAIN_FLOOR * maxima[l]);
            trial[l] *= (implied / support_gain).powf(step);
        }
        if !normalise(&mut trial[..n]) {
            break;
        }
        let mut trial_y = y;
        let (bound, trial_support, trial_g) = evaluate(&trial, &mut trial_y, &costs);
        let Some(bound) = bound else {
            return (f64::NEG_INFINITY, None);
        };
        if bound < best {
            (w, y, support, g, best) = (trial, trial_y, trial_support, trial_g, bound);
            step = (step * 1.5).min(DIRECTION_STEP);
        } else {
            step *= 0.25;
        }
    }
    (best, Some((y, w)))
}

/// Scales weights to sum 1, each at least [`WEIGHT_FLOOR`]; `false` if they cannot be (zero,
/// infinite or NaN).
fn normalise(w: &mut [f64]) -> bool {
    let total: f64 = w.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return false;
    }
    for x in w.iter_mut() {
        *x = (*x / total).max(WEIGHT_FLOOR);
    }
    true
}

/// The channel ordering's multipliers for a direction w (NOMA): g = w + Dᵀμ, μ ≥ 0, where
/// (Dλ)_t = λ_{π[t]} − λ_{π[t+1]} ≤ 0 on the order's region, so g·λ ≤ w·λ there and the
/// half-space bound with g is valid. The best μ maximises Σ_l √(c_l g_l) (the tighter the
/// bound): each μ_t moves weight from position t + 1 to position t, and the optimum pools
/// adjacent positions whose implied gains √(c/g) would break the ordering, giving a pooled block
/// g_l = c_l·W/C (W, C its weight and cost): the pool-adjacent-violators algorithm. μ is then
/// read back from the prefix sums, clamped at 0 and g rebuilt from it exactly, so rounding can
/// never make the bound invalid (g = w if that fails). OMA has no ordering: g = w.
fn ordered_weights(w: &[f64], costs: &[f64], pi: &[u8], access: Access) -> [f64; MOST_USERS] {
    let n = w.len();
    let mut g = [0.0; MOST_USERS];
    g[..n].copy_from_slice(w);
    if access != Access::Noma {
        return g;
    }
    // Blocks of (cost, weight, positions); a block's implied gain is √(C/W).
    let mut blocks = [(0.0, 0.0, 0usize); MOST_USERS];
    let mut len = 0;
    for &u in pi {
        let u = u as usize;
        blocks[len] = (costs[u], w[u], 1);
        len += 1;
        while len > 1 {
            let (c1, w1, k1) = blocks[len - 1];
            let (c0, w0, k0) = blocks[len - 2];
            if c0 * w1 <= c1 * w0 {
                break; // √(c0/w0) ≤ √(c1/w1): ordered
            }
            blocks[len - 2] = (c0 + c1, w0 + w1, k0 + k1);
            len -= 1;
        }
    }
    let mut t = 0;
    let mut pooled = [0.0; MOST_USERS];
    for &(c, weight, count) in &blocks[..len] {
        for _ in 0..count {
            let u = pi[t] as usize;
            pooled[u] = if c > 0.0 { costs[u] * weight / c } else { w[u] };
            t += 1;
        }
    }
    // μ_t = Σ_{u ≤ t} (g − w) along the order, then g = w + Dᵀμ exactly.
    let mut mu = [0.0; MOST_USERS];
    let mut prefix = 0.0;
    for t in 0..n - 1 {
        let u = pi[t] as usize;
        prefix += pooled[u] - w[u];
        mu[t] = prefix.max(0.0);
    }
    for t in 0..n {
        let u = pi[t] as usize;
        let from_before = if t > 0 { mu[t - 1] } else { 0.0 };
        let to_here = if t + 1 < n { mu[t] } else { 0.0 };
        g[u] = w[u] + to_here - from_before;
    }
    if g[..n].iter().any(|x| x.is_nan() || *x < 0.0) {
        g[..n].copy_from_slice(w);
    }
    g
}

/// The dual iterate Y's start: the rank-one Λ = y yᴴ that a rank-one relaxation would have at
/// the hint (y_l = √w_l·a_lᵀv), plus a small multiple of the identity so the power iteration
/// can leave rank one where the relaxation is not tight.
fn seed_dual(y: &mut Square, amplitudes: &[C64; MOST_USERS], w: &[f64], n: usize) {
    let norm: f64 = (0..n)
        .map(|l| w[l] * amplitudes[l].norm_sqr())
        .sum::<f64>()
        .sqrt();
    for (l, row) in y.iter_mut().enumerate().take(n) {
        for (j, cell) in row.iter_mut().enumerate().take(n) {
            *cell = C64::new(if l == j { SEED_IDENTITY } else { 0.0 }, 0.0);
        }
        if norm > 0.0 {
            row[0] += amplitudes[l] * (w[l].sqrt() / norm);
        }
    }
}

/// Gains moved into the order's region: pooled where they break its channel ordering (the
/// isotonic regression along the order, NOMA only), capped by [`order_caps`] and kept
/// positive.
fn project_onto_order(lambda: &mut [f64], pi: &[u8], maxima: &[f64; MOST_USERS], access: Access) {
    let n = lambda.len();
    if access == Access::Noma {
        // Pool adjacent violators: blocks of (sum, count) along the order.
        let mut blocks: Vec<(f64, usize)> = Vec::with_capacity(n);
        for &u in pi {
            blocks.push((lambda[u as usize], 1));
            while blocks.len() > 1 {
                let (s1, c1) = blocks[blocks.len() - 1];
                let (s0, c0) = blocks[blocks.len() - 2];
                if s0 / c0 as f64 <= s1 / c1 as f64 {
                    break;
                }
                blocks.pop();
                *blocks.last_mut().expect("two blocks") = (s0 + s1, c0 + c1);
            }
        }
        let mut t = 0;
        for (sum, count) in blocks {
            for _ in 0..count {
                lambda[pi[t] as usize] = sum / count as f64;
                t += 1;
            }
        }
    }
    let caps = order_caps(pi, maxima, access);
    for &u in pi {
        let u = u as usize;
        lambda[u] = lambda[u].min(caps[u]).max(GAIN_FLOOR * maxima[u]);
    }
}

/// [`joint_support`]'s valid upper bound on h(w), from a cold start (Λ = I/(K+1)): the
/// support bound for any number of users.
pub fn joint_support_bound(problem: &CellProblem, w: &[f64]) -> f64 {
    let n = w.len();
    let mut y = [[C64::new(0.0, 0.0); MOST_USERS]; MOST_USERS];
    for (l, row) in y.iter_mut().enumerate().take(n) {
        row[l] = C64::new(1.0 / (n as f64).sqrt(), 0.0);
    }
    joint_support(problem, w, &mut y).bound
}

/// The dual iterate of [`joint_support`]: Y with Λ = Y Yᴴ, row l = user l.
type Square = [[C64; MOST_USERS]; MOST_USERS];

/// A valid upper bound on h(w) and the support point's estimate.
struct Support {
    bound: f64,
    /// ∂h/∂w_l at the final iterate: the relaxed gains (without τ) that attain h(w).
    point: [f64; MOST_USERS],
}

/// A valid upper bound on h(w) = max{Σ_l w_l tr(A_l V) : V ⪰ 0, diag V = 1} for any number of
/// users, the K ≥ 2 form of [`support_bound`].
///
/// With ρ_n = (√w_l a_{l,n})_l ∈ C^{K+1}, SDP duality gives h(w) = max over Λ ⪰ 0, tr Λ = 1 of
/// G(Λ)² with G = Σ_n √(ρ_nᴴ Λ ρ_n), and any Λ yields the valid bound λ_max(M) · G with
/// M = Σ_n ρ_n ρ_nᴴ / √(ρ_nᴴ Λ ρ_n) (z_n = 1/√(ρ_nᴴΛρ_n), scaled feasible). Writing Λ = Y Yᴴ
/// with ‖Y‖_F = 1, G(Y) = Σ_n ‖Yᴴρ_n‖ is *convex* in Y and its gradient is M Y, so the
/// projected step Y ← M Y / ‖M Y‖_F never lowers G (G(Y') ≥ G(Y) + ⟨MY, Y' − Y⟩ ≥ G(Y)): a
/// power iteration whose fixed points put Y in M's top eigenspace, where the bound meets G².
/// It stops when the two agree to [`JOINT_TOLERANCE`].
fn joint_support(problem: &CellProblem, w: &[f64], y: &mut Square) -> Support {
    let n = w.len();
    let mut root_w = [0.0; MOST_USERS];
    for l in 0..n {
        root_w[l] = w[l].sqrt();
    }
    let mut best = Support {
        bound: f64::INFINITY,
        point: [0.0; MOST_USERS],
    };
    // G(Y)² is a lower estimate of h only at ‖Y‖_F = 1, and the stopping test relies on it.
    let start: f64 = y[..n]
        .iter()
        .flat_map(|row| &row[..n])
        .map(|c| c.norm_sqr())
        .sum();
    if start > 0.0 {
        let scale = 1.0 / start.sqrt();
        for row in &mut y[..n] {
            for cell in &mut row[..n] {
                *cell *= scale;
            }
        }
    }
    let pass = |y: &Square, m: &mut Matrix5, slope: Option<&mut [f64; MOST_USERS]>| match n {
        1 => joint_pass::<1>(problem, &root_w, y, m, slope),
        2 => joint_pass::<2>(problem, &root_w, y, m, slope),
        3 => joint_pass::<3>(problem, &root_w, y, m, slope),
        4 => joint_pass::<4>(problem, &root_w, y, m, slope),
        5 => joint_pass::<5>(problem, &root_w, y, m, slope),
        _ => unreachable!("callers admit 1..={MOST_USERS} users"),
    };
    let mut m = Matrix5::zeros();
    let mut best_y = *y;
    for _ in 0..JOINT_STEPS {
        let g = pass(y, &mut m, None);
        let top = m
            .view((0, 0), (n, n))
            .clone_owned()
            .symmetric_eigenvalues()
            .max();
        let bound = top * g;
        if bound < best.bound {
            best.bound = bound;
            best_y = *y;
        }
        if best.bound <= g * g * (1.0 + JOINT_TOLERANCE) {
            break;
        }
        // Y ← M Y / ‖M Y‖_F.
        let mut next = [[C64::new(0.0, 0.0); MOST_USERS]; MOST_USERS];
        let mut norm = 0.0;
        for l in 0..n {
            for j in 0..n {
                let mut sum = C64::new(0.0, 0.0);
                for k in 0..n {
                    sum += m[(l, k)] * y[k][j];
                }
                next[l][j] = sum;
                norm += sum.norm_sqr();
            }
        }
        let scale = 1.0 / norm.sqrt();
        for l in 0..n {
            for j in 0..n {
                y[l][j] = next[l][j] * scale;
            }
        }
    }
    // The support point at the iterate of the best bound: ∂h/∂w_l = G Σ_n z_n Re(…)/w_l.
    let mut slope = [0.0; MOST_USERS];
    let g = pass(&best_y, &mut m, Some(&mut slope));
    for l in 0..n {
        best.point[l] = g * slope[l] / (root_w[l] * root_w[l]);
    }
    best
}

/// One pass of [`joint_support`] over the elements at Y, for N users: returns G and fills M
/// (its upper triangle summed, the lower mirrored, Hermitian) and, when asked, the support
/// point's sums Σ_n z_n Re(conj(ρ_{n,l}) (Y t_n)_l), which only the best iterate needs. The
/// number of users is a constant so that the loops over them unroll and M's sums stay in
/// registers: this pass is most of a K ≥ 2 map's certificate. Every sum runs over the elements
/// in order, as a loop over any number of users would.
fn joint_pass<const N: usize>(
    problem: &CellProblem,
    root_w: &[f64; MOST_USERS],
    y: &Square,
    m: &mut Matrix5,
    slope: Option<&mut [f64; MOST_USERS]>,
) -> f64 {
    let dim = problem.dim;
    let zero = C64::new(0.0, 0.0);
    let mut upper = [[zero; N]; N];
    let mut g = 0.0;
    let mut sums = [0.0; N];
    let want_slope = slope.is_some();
    for e in 0..dim {
        let mut rho = [zero; N];
        let mut alpha = 0.0;
        for l in 0..N {
            rho[l] = problem.a[l * dim + e] * root_w[l];
            alpha += rho[l].norm_sqr();
        }
        // t = Yᴴρ, q = ‖t‖².
        let mut t = [zero; N];
        let mut q = 0.0;
        for (j, tj) in t.iter_mut().enumerate() {
            let mut sum = zero;
            for l in 0..N {
                sum += y[l][j].conj() * rho[l];
            }
            *tj = sum;
            q += sum.norm_sqr();
        }
        let root = q.max(1e-14 * alpha + f64::MIN_POSITIVE).sqrt();
        let z = 1.0 / root;
        g += root;
        for l in 0..N {
            let zr = rho[l] * z;
            for k in l..N {
                upper[l][k] += zr * rho[k].conj();
            }
        }
        if want_slope {
            for l in 0..N {
                let mut yt = zero;
                for j in 0..N {
                    yt += y[l][j] * t[j];
                }
                sums[l] += z * (rho[l].conj() * yt).re;
            }
        }
    }
    m.fill(zero);
    for l in 0..N {
        m[(l, l)] = upper[l][l];
        for k in l + 1..N {
            m[(l, k)] = upper[l][k];
            m[(k, l)] = upper[l][k].conj();
        }
    }
    if let Some(slope) = slope {
        slope[..N].copy_from_slice(&sums);
    }
    g
}

/// A valid upper bound on h(w) = max{w₁ tr(ā āᴴ V) + w₂ tr(b̄ b̄ᴴ V) : V ⪰ 0, diag V = 1}.
pub fn support_bound(a: &[C64], b: &[C64], w1: f64, w2: f64) -> f64 {
    support_bound_from(a, b, w1, w2, None).0
}

/// [`support_bound`], warm-started from the dual point of a nearby direction; returns the bound
/// and this direction's dual point (the Bloch vector x of Λ).
fn support_bound_from(
    a: &[C64],
    b: &[C64],
    w1: f64,
    w2: f64,
    start: Option<Vector3<f64>>,
) -> (f64, Vector3<f64>) {
    if w2 <= 0.0 {
        return (w1 * l1_norm(a).powi(2), Vector3::new(0.0, 0.0, 1.0)); // rank one: the relaxation is tight
    }
    if w1 <= 0.0 {
        return (w2 * l1_norm(b).powi(2), Vector3::new(0.0, 0.0, -1.0));
    }
    let rw = (w1 * w2).sqrt();
    // u_n(x) = 2 ρ_nᴴ Λ ρ_n = α_n + β_n·x, with |β_n| = α_n.
    let alpha: Vec<f64> = a
        .iter()
        .zip(b)
        .map(|(p, q)| w1 * p.norm_sqr() + w2 * q.norm_sqr())
        .collect();
    let beta: Vec<Vector3<f64>> = a
        .iter()
        .zip(b)
        .map(|(p, q)| {
            let c = p.conj() * q * rw;
            Vector3::new(
                2.0 * c.re,
                2.0 * c.im,
                w1 * p.norm_sqr() - w2 * q.norm_sqr(),
            )
        })
        .collect();
    let floor = |al: f64| 1e-14 * al + f64::MIN_POSITIVE;
    let value = |x: &Vector3<f64>| -> f64 {
        alpha
            .iter()
            .zip(&beta)
            .map(|(al, be)| (al + be.dot(x)).max(0.0).sqrt())
            .sum()
    };
    // Any Λ (any x) yields the valid bound λ_max(M) · Σ 1/z_n, and (Σ √q_n)² ≤ h(w) is a lower
    // estimate: iterate until the two agree to `GAP_TOLERANCE`.
    let certified = |x: &Vector3<f64>| -> (f64, f64) {
        let (mut m11, mut m22, mut m12) = (0.0, 0.0, C64::new(0.0, 0.0));
        let mut sqrt_sum = 0.0;
        for ((al, be), (p, q)) in alpha.iter().zip(&beta).zip(a.iter().zip(b)) {
            let q_n = 0.5 * (al + be.dot(x)).max(floor(*al));
            let z = 1.0 / q_n.sqrt();
            sqrt_sum += q_n.sqrt();
            m11 += z * w1 * p.norm_sqr();
            m22 += z * w2 * q.norm_sqr();
            m12 += p * q.conj() * (z * rw);
        }
        let lambda_max = 0.5 * (m11 + m22) + (0.25 * (m11 - m22).powi(2) + m12.norm_sqr()).sqrt();
        (lambda_max * sqrt_sum, sqrt_sum * sqrt_sum)
    };
    // Maximise the concave G(x) = Σ √(α_n + β_n·x) over the unit ball by Newton steps whose
    // quadratic model is maximised over the ball itself ([`ball_newton_point`]): optima on the
    // sphere (rank-one Λ, a tight relaxation) and inside it are reached the same way, without a
    // barrier's stages. Stop once the certified gap closes.
    let mut x = start.unwrap_or_else(Vector3::zeros);
    let mut current = value(&x);
    let mut best_bound = f64::INFINITY;
    for _ in 0..MAX_NEWTON_STEPS {
        let (bound, lower) = certified(&x);
        best_bound = best_bound.min(bound);
        if best_bound <= lower * (1.0 + GAP_TOLERANCE) {
            break;
        }
        // ∇G and −∇²G at x (terms at the floor keep both finite).
        let mut grad = Vector3::zeros();
        let mut neg_hess = Matrix3::zeros();
        for (al, be) in alpha.iter().zip(&beta) {
            let u = (al + be.dot(&x)).max(floor(*al));
            let su = u.sqrt();
            grad += be / (2.0 * su);
            neg_hess += be * be.transpose() / (4.0 * u * su);
        }
        let target = ball_newton_point(&neg_hess, &(grad + neg_hess * x));
        let direction = target - x;
        // G is concave and the ball convex: every point towards the model's maximiser is
        // feasible; halve the step until G rises (the model is exact to second order).
        let mut t = 1.0;
        let mut moved = false;
        for _ in 0..LINE_SEARCH_HALVINGS {
            let candidate = x + direction * t;
            let candidate_value = value(&candidate);
            if candidate_value > current {
                (x, current, moved) = (candidate, candidate_value, true);
                break;
            }
            t *= 0.5;
        }
        if !moved {
            // At rounding: x is as good as this arithmetic tells; its bound is the answer.
            best_bound = best_bound.min(certified(&x).0);
            break;
        }
    }
    (best_bound, x)
}

/// The maximiser over the unit ball of the concave quadratic model cᵀy − ½ yᵀHy (H = −∇²G ⪰ 0,
/// c = ∇G + Hx, so the model is G's second-order expansion around x written in y): the Newton
/// point H⁻¹c when it lies in the ball, else y(ν) = (H + νI)⁻¹c on the sphere, with ν > 0 the
/// root of the secular equation 1/‖y(ν)‖ = 1 (Moré–Sorensen), found by Newton's method on
/// that nearly linear function, safeguarded by bisection on [0, ‖c‖] (at ν = ‖c‖, ‖y‖ ≤ 1).
fn ball_newton_point(h: &Matrix3<f64>, c: &Vector3<f64>) -> Vector3<f64> {
    let solve = |nu: f64| (h + Matrix3::identity() * nu).cholesky();
    if let Some(chol) = solve(0.0) {
        let y = chol.solve(c);
        if y.norm_squared() <= 1.0 {
            return y;
        }
    }
    let (mut lo, mut hi) = (0.0, c.norm());
    let mut nu = hi;
    let mut best = c / c.norm().max(f64::MIN_POSITIVE);
    for _ in 0..SECULAR_STEPS {
        let Some(chol) = solve(nu) else {
            lo = nu;
            nu = 0.5 * (lo + hi);
            continue;
        };
        let y = chol.solve(c);
        let r = y.norm();
        if r > 1.0 {
            lo = nu;
        } else {
            hi = nu;
            best = y;
        }
        if (r - 1.0).abs() <= SECULAR_TOLERANCE {
            return y / r;
        }
        // d‖y‖/dν = −yᵀ(H + νI)⁻¹y / ‖y‖; Newton on 1/‖y‖ − 1.
        let slope = -y.dot(&chol.solve(&y)) / r;
        let newton = nu + (1.0 / r - 1.0) * r * r / slope;
        nu = if newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
    }
    best / best.norm().max(1.0)
}

type Point = [f64; 2];

/// Keeps the part of a convex polygon with n·p ≤ c (Sutherland–Hodgman, one half-plane).
fn clip(polygon: &[Point], n: Point, c: f64) -> Vec<Point> {
    let inside = |p: &Point| n[0] * p[0] + n[1] * p[1] <= c;
    let mut out = Vec::with_capacity(polygon.len() + 1);
    for k in 0..polygon.len() {
        let (p, q) = (polygon[k], polygon[(k + 1) % polygon.len()]);
        let (ip, iq) = (inside(&p), inside(&q));
        if ip {
            out.push(p);
        }
        if ip != iq {
            let fp = n[0] * p[0] + n[1] * p[1] - c;
            let fq = n[0] * q[0] + n[1] * q[1] - c;
            let t = fp / (fp - fq);
            out.push([p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])]);
        }
    }
    out
}

/// The K = 1 bound: outer polygon of the relaxed gain set, maximised per decoding order.
fn polygon_bound(problem: &CellProblem, model: &RateModel) -> f64 {
    let (a, b) = (problem.user(0), problem.user(1));
    let tau = [problem.tau[0], problem.tau[1]];
    // (angle, bound, dual point), kept sorted by angle.
    let mut directions: Vec<(f64, f64, Vector3<f64>)> = Vec::new();
    let mut previous = None;
    for k in 0..INITIAL_DIRECTIONS {
        let angle = FRAC_PI_2 * k as f64 / (INITIAL_DIRECTIONS - 1) as f64;
        let (h, x) = support_bound_from(a, b, angle.cos(), angle.sin(), previous);
        previous = (k > 0).then_some(x);
        directions.push((angle, h, x));
    }
    let mut best = f64::INFINITY;
    for round in 0..=REFINEMENT_ROUNDS {
        let (value, argmax) = maximise_over_polygon(&directions, tau, model);
        let settled = best - value < REFINEMENT_SETTLED;
        best = value;
        let Some(point) = argmax else { break };
        if round == REFINEMENT_ROUNDS || (settled && round >= 2) {
            break;
        }
        // Refine between each active direction and its neighbours.
        let mut new_angles = Vec::new();
        for (k, &(angle, h, _)) in directions.iter().enumerate() {
            let residual = h - (angle.cos() * point[0] + angle.sin() * point[1]);
            if residual <= 1e-9 * h.max(f64::MIN_POSITIVE) {
                if k > 0 {
                    new_angles.push((0.5 * (angle + directions[k - 1].0), k - 1));
                }
                if k + 1 < directions.len() {
                    new_angles.push((0.5 * (angle + directions[k + 1].0), k + 1));
                }
            }
        }
        new_angles.retain(|t| directions.iter().all(|d| (d.0 - t.0).abs() > 1e-6));
        new_angles.dedup_by(|p, q| (p.0 - q.0).abs() < 1e-9);
        if new_angles.is_empty() {
            break;
        }
        for (angle, neighbour) in new_angles {
            let warm = directions[neighbour].2;
            let start = (directions[neighbour].0 > 0.0 && directions[neighbour].0 < FRAC_PI_2)
                .then_some(warm);
            let (h, x) = support_bound_from(a, b, angle.cos(), angle.sin(), start);
            directions.push((angle, h, x));
        }
        directions.sort_by(|p, q| p.0.total_cmp(&q.0));
    }
    best
}

/// Max of the MRU rate over the outer polygon (in gain coordinates without τ) and every order;
/// returns the value and the maximiser (without τ), if any polygon is non-empty.
fn maximise_over_polygon(
    directions: &[(f64, f64, Vector3<f64>)],
    tau: [f64; 2],
    model: &RateModel,
) -> (f64, Option<Point>) {
    let x_max = directions.first().map_or(0.0, |d| d.1);
    let y_max = directions.last().map_or(0.0, |d| d.1);
    let mut polygon: Vec<Point> = vec![[0.0, 0.0], [x_max, 0.0], [x_max, y_max], [0.0, y_max]];
    for &(angle, h, _) in &directions[1..directions.len() - 1] {
        polygon = clip(&polygon, [angle.cos(), angle.sin()], h);
    }
    let polygon: Vec<Point> = polygon
        .iter()
        .map(|p| [p[0] + tau[0], p[1] + tau[1]])
        .collect();
    let mut best = (f64::NEG_INFINITY, None);
    for k in 0..model.orders().len() {
        let mut region = polygon.clone();
        // SIC channel ordering: λ_{π[t]} ≤ λ_{π[t+1]}.
        if model.access == Access::Noma {
            let pi = &model.orders()[k];
            let mut n = [0.0, 0.0];
            n[pi[0] as usize] = 1.0;
            n[pi[1] as usize] = -1.0;
            region = clip(&region, n, 0.0);
        }
        // The SRU must be servable at all: λ_s ≥ (power it needs at unit gain) / P_max.
        let lambda_s_min = model.required_power(&[1.0, 1.0], k, 0.0) / model.p_max_w;
        region = clip(&region, [0.0, -1.0], -lambda_s_min);
        if region.is_empty() {
            continue;
        }
        // Scores order like rates (the same log2 for every order): one logarithm at the end.
        let score = |p: &Point| {
            model
                .mru_score_ignoring_ordering(p, k)
                .unwrap_or(f64::NEG_INFINITY)
        };
        for e in 0..region.len() {
            let (p, q) = (region[e], region[(e + 1) % region.len()]);
            let at = |t: f64| [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])];
            let (t, value) = max_on_segment(|t| score(&at(t)));
            if value > best.0 {
                best = (value, Some(at(t)));
            }
        }
    }
    let argmax = best.1.map(|p| [p[0] - tau[0], p[1] - tau[1]]);
    (model.rate_of_score(best.0), argmax)
}

/// Maximum of a unimodal function on [0, 1], endpoints included (the maximum of a
/// quasi-concave rate over an edge may sit at a vertex).
fn max_on_segment(f: impl Fn(f64) -> f64) -> (f64, f64) {
    let interior = golden_section_max(&f, 0.0, 1.0, EDGE_SEARCH_STEPS);
    [(0.0, f(0.0)), (1.0, f(1.0)), interior].into_iter().fold(
        (0.0, f64::NEG_INFINITY),
        |best, c| {
            if c.1 > best.1 { c } else { best }
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn random_vector(rng: &mut impl RngExt, n: usize) -> Vec<C64> {
        (0..n)
            .map(|_| C64::new(rng.random::<f64>() - 0.5, rng.random::<f64>() - 0.5))
            .collect()
    }

    /// The support bound is ≥ every rank-one value and ≥ the dual's lower estimate, and it is
    /// attained by rank-one points when one weight vanishes.
    #[test]
    fn support_bound_dominates_rank_one_points() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for _ in 0..20 {
            let n = rng.random_range(2..12);
            let (a, b) = (random_vector(&mut rng, n), random_vector(&mut rng, n));
            let angle = rng.random::<f64>() * FRAC_PI_2;
            let (w1, w2) = (angle.cos(), angle.sin());
            let bound = support_bound(&a, &b, w1, w2);
            for _ in 0..2000 {
                let v: Vec<C64> = (0..n)
                    .map(|_| C64::from_polar(1.0, rng.random::<f64>() * 6.3))
                    .collect();
                let sa: C64 = a.iter().zip(&v).map(|(x, y)| x * y).sum();
                let sb: C64 = b.iter().zip(&v).map(|(x, y)| x * y).sum();
                assert!(w1 * sa.norm_sqr() + w2 * sb.norm_sqr() <= bound * (1.0 + 1e-12));
            }
        }
    }

    /// The bound is tight where the SDR is: b = c·a makes W rank one, so h(w) is known exactly.
    #[test]
    fn support_bound_is_tight_for_parallel_users() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let a = random_vector(&mut rng, 9);
        let c = C64::new(0.3, -1.2);
        let b: Vec<C64> = a.iter().map(|x| x * c).collect();
        let (w1, w2) = (0.6, 0.8);
        let exact = (w1 + w2 * c.norm_sqr()) * l1_norm(&a).powi(2);
        let bound = support_bound(&a, &b, w1, w2);
        assert!(
            bound >= exact * (1.0 - 1e-12) && bound <= exact * (1.0 + 1e-6),
            "{bound} vs {exact}"
        );
    }

    /// The joint support bound is ≥ every rank-one value Σ w_l |a_lᵀv|², and exact where the
    /// relaxation is: users whose a-vectors are parallel make W rank one.
    #[test]
    fn joint_support_bound_dominates_rank_one_points_and_is_tight_when_parallel() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(23);
        for case in 0..24 {
            let users = 3 + case % 3;
            let dim = rng.random_range(2..12);
            let parallel = case % 4 == 0;
            let base = random_vector(&mut rng, dim);
            let mut a = Vec::new();
            let mut scales = Vec::new();
            for _ in 0..users {
                if parallel {
                    let c = C64::new(rng.random::<f64>() + 0.1, rng.random::<f64>() - 0.5);
                    a.extend(base.iter().map(|x| x * c));
                    scales.push(c.norm_sqr());
                } else {
                    a.extend(random_vector(&mut rng, dim));
                }
            }
            let problem = CellProblem {
                dim,
                a,
                tau: vec![0.0; users],
            };
            let w: Vec<f64> = (0..users).map(|_| rng.random::<f64>() + 0.01).collect();
            let bound = joint_support_bound(&problem, &w);
            if parallel {
                let exact: f64 =
                    w.iter().zip(&scales).map(|(w, s)| w * s).sum::<f64>() * l1_norm(&base).powi(2);
                assert!(
                    bound >= exact * (1.0 - 1e-12) && bound <= exact * (1.0 + 1e-6),
                    "{bound} vs {exact}"
                );
            }
            let mut lambdas = vec![0.0; users];
            for _ in 0..2000 {
                let v: Vec<C64> = (0..dim)
                    .map(|_| C64::from_polar(1.0, rng.random::<f64>() * 6.3))
                    .collect();
                problem.lambdas(&v, &mut lambdas);
                let value: f64 = w.iter().zip(&lambdas).map(|(w, l)| w * l).sum();
                assert!(value <= bound * (1.0 + 1e-12), "{value} > {bound}");
            }
        }
    }

    /// [`ordered_weights`] returns g = w + Dᵀμ with μ ≥ 0 (so the bound stays valid) and g ≥ 0,
    /// and no other such g has a larger Σ √(c_l g_l).
    #[test]
    fn ordering_multipliers_are_valid_and_best() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(31);
        for case in 0..300 {
            let n = 2 + case % 4;
            let model = RateModel::new(Access::Noma, 1.0, 1.0, &vec![0.5; n - 1]);
            let order = rng.random_range(0..model.orders().len());
            let pi = &model.orders()[order];
            let w: Vec<f64> = (0..n).map(|_| rng.random::<f64>().powi(3) + 1e-6).collect();
            let c: Vec<f64> = (0..n).map(|_| rng.random::<f64>().powi(3) + 1e-6).collect();
            let g = ordered_weights(&w, &c, pi, Access::Noma);
            let objective = |g: &[f64]| -> f64 { (0..n).map(|l| (c[l] * g[l]).sqrt()).sum() };
            // μ_t is the prefix sum of g − w along the order; the last one closes at 0.
            let mut prefix = 0.0;
            for (t, &u) in pi.iter().enumerate() {
                let u = u as usize;
                assert!(g[u] >= 0.0);
                prefix += g[u] - w[u];
                let tolerance = 1e-12 * w.iter().sum::<f64>();
                if t + 1 < n {
                    assert!(prefix >= -tolerance, "μ_{t} = {prefix} < 0");
                } else {
                    assert!(prefix.abs() <= tolerance, "weight not conserved: {prefix}");
                }
            }
            let best = objective(&g[..n]);
            for _ in 0..200 {
                let mu: Vec<f64> = (0..n - 1).map(|_| rng.random::<f64>() * 0.5).collect();
                let mut other = w.clone();
                for t in 0..n - 1 {
                    other[pi[t] as usize] += mu[t];
                    other[pi[t + 1] as usize] -= mu[t];
                }
                if other.iter().all(|x| *x >= 0.0) {
                    assert!(objective(&other) <= best * (1.0 + 1e-12));
                }
            }
        }
    }

    #[test]
    fn clipping_keeps_the_right_side() {
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let half = clip(&square, [1.0, 1.0], 1.0);
        let area: f64 = (0..half.len())
            .map(|k| {
                let (p, q) = (half[k], half[(k + 1) % half.len()]);
                p[0] * q[1] - q[0] * p[1]
            })
            .sum::<f64>()
            / 2.0;
        assert!((area - 0.5).abs() < 1e-12);
    }
}
