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
//! For K > 1 the relaxed gains live in R^{K+1}; there we use the looser bound of each user's own
//! maximum, λ_l ≤ (‖a_l‖₁)² + τ_l (exact for a single user), with the ordering constraints
//! dropped — still valid because the rate of every order increases in every gain.

use super::CellProblem;
use crate::channel::C64;
use crate::numerics::{golden_section_max, l1_norm};
use crate::rate::{Access, RateModel};
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
/// Golden-section steps per polygon edge: 0.618^60 ≈ 3e-13 of the edge, i.e. to rounding.
const EDGE_SEARCH_STEPS: usize = 60;

/// An upper bound on the MRU's rate over all phase vectors (−∞ if even the relaxation cannot
/// serve every SRU).
pub fn upper_bound(problem: &CellProblem, model: &RateModel) -> f64 {
    if problem.users() == 2 {
        polygon_bound(problem, model)
    } else {
        per_user_bound(problem, model)
    }
}

fn per_user_bound(problem: &CellProblem, model: &RateModel) -> f64 {
    let lambdas: Vec<f64> = (0..problem.users()).map(|l| problem.max_gain(l)).collect();
    (0..model.orders().len())
        .filter_map(|k| model.mru_rate_ignoring_ordering(&lambdas, k))
        .fold(f64::NEG_INFINITY, f64::max)
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
