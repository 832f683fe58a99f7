//! Rate-map solvers (docs/model.md §5): per cell, the IRS phases θ that maximise the MRU's
//! expected rate while every SRU meets its own, with the power split and decoding order in
//! closed form ([`crate::rate`]).
//!
//! Per cell the problem only sees, for each user l, the vector a_l = [w̃_l; h̃_l] ∈ C^{N+1} and
//! the scattered power τ_l, because λ_l(θ) = |a_lᵀ v|² + τ_l with v = [θ; 1] (paper eqs. 27–28).
//!
//! * [`fast`] (default): the stationary-point family searched and refined.
//! * [`certificate`]: an upper bound from the semidefinite relaxation, computed without an SDP
//!   solver, reported per cell as `upper_bound` and `gap`.
//! * `sdr_sca` (cargo feature `sdp`): the paper's Algorithms 1–2 on Clarabel.
//!
//! Phase modes: `none` has no IRS term (θ is empty); `bits: b` projects the continuous solution
//! onto the L = 2^b levels and re-optimises element by element over those levels
//! ([`fast::discrete_ascent`]); the certificate of the continuous problem still bounds it.

pub mod certificate;
pub mod fast;
#[cfg(feature = "sdp")]
pub mod sdr_sca;

use crate::channel::{C64, ChannelModel};
use crate::numerics::l1_norm;
use crate::phases::PhaseMode;
use crate::rate::RateModel;
use crate::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

/// Which method solves each rate-map cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SolverKind {
    /// The stationary-point family search of [`fast`] (default).
    #[serde(rename = "fast")]
    Fast,
    /// The paper's SDR + SCA on Clarabel (cargo feature `sdp`).
    #[serde(rename = "sdr-sca")]
    SdrSca,
}

impl SolverKind {
    /// Whether this build can run the solver (`sdr-sca` needs the cargo feature `sdp`).
    pub const fn is_available(self) -> bool {
        match self {
            SolverKind::Fast => true,
            SolverKind::SdrSca => cfg!(feature = "sdp"),
        }
    }
}

impl FromStr for SolverKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::input::parse_name(s)
    }
}

impl fmt::Display for SolverKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            SolverKind::Fast => "fast",
            SolverKind::SdrSca => "sdr-sca",
        })
    }
}

/// One cell's rate problem: a_l and τ_l for every user (0 = MRU, then the SRUs).
#[derive(Debug, Clone)]
pub struct CellProblem {
    /// N + 1 (the last entry of each a_l is h̃_l, paired with v_{N+1} = 1).
    pub dim: usize,
    /// a_l stacked: user l occupies `a[l·dim .. (l+1)·dim]`.
    pub a: Vec<C64>,
    /// τ_l per user (linear): the scattered power the phases cannot steer.
    pub tau: Vec<f64>,
}

impl CellProblem {
    /// K + 1: the users of the problem, MRU first.
    pub fn users(&self) -> usize {
        self.tau.len()
    }
    /// a_l of user `l` (N + 1 coefficients).
    pub fn user(&self, l: usize) -> &[C64] {
        &self.a[l * self.dim..(l + 1) * self.dim]
    }
    /// User l's own best gain over all phases, ‖a_l‖₁² + τ_l (eq. 12 for that user alone): an
    /// upper bound on λ_l that the relaxation attains, since a_l a_lᴴ has rank one.
    pub fn max_gain(&self, l: usize) -> f64 {
        l1_norm(self.user(l)).powi(2) + self.tau[l]
    }

    /// λ_l(v) = |a_lᵀ v|² + τ_l for every user.
    pub fn lambdas(&self, v: &[C64], out: &mut [f64]) {
        for (l, o) in out.iter_mut().enumerate() {
            let s: C64 = self.user(l).iter().zip(v).map(|(a, x)| a * x).sum();
            *o = s.norm_sqr() + self.tau[l];
        }
    }
}

/// The MRU's best rate for given gains over every admissible order, −∞ if an SRU cannot be
/// served. Allocation-free.
#[inline]
pub fn objective(model: &RateModel, lambdas: &[f64]) -> f64 {
    model.rate_of_score(score(model, lambdas))
}

/// [`objective`] before its logarithm: the best [`RateModel::mru_score`] over the admissible
/// orders (−∞ if an SRU cannot be served), the inner objective of the searches.
#[inline]
pub fn score(model: &RateModel, lambdas: &[f64]) -> f64 {
    model
        .best_order(lambdas)
        .map_or(f64::NEG_INFINITY, |(score, _)| score)
}

/// A solved cell: the phases (v normalised so v_{N+1} = 1) and the certificate.
#[derive(Debug, Clone)]
pub struct CellSolution {
    /// v = [e^{jθ}; 1].
    pub v: Vec<C64>,
    /// The achieved MRU rate (−∞ if no configuration serves every SRU).
    pub rate: f64,
    /// The SDR upper bound on any achievable rate (−∞ if even the relaxation cannot serve the SRUs).
    pub upper_bound: f64,
}

/// The per-user vectors at one MRU location, sharing the SRUs' precomputed part.
pub fn cell_problem(
    model: &ChannelModel,
    mru: [f64; 3],
    srus: &CellProblem,
    with_irs: bool,
) -> CellProblem {
    let n = if with_irs { model.subsurfaces() } else { 0 };
    let dim = n + 1;
    let mut a = Vec::with_capacity(srus.a.len() + dim);
    let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
    let d = model.evaluate(mru, with_irs, &mut w);
    a.extend_from_slice(&w[..n]);
    a.push(d.h);
    a.extend_from_slice(&srus.a);
    let mut tau = vec![d.tau];
    tau.extend_from_slice(&srus.tau);
    CellProblem { dim, a, tau }
}

/// The SRUs' a_l and τ_l, which do not depend on the MRU's cell.
pub fn sru_part(model: &ChannelModel, scenario: &Scenario, with_irs: bool) -> CellProblem {
    let n = if with_irs { model.subsurfaces() } else { 0 };
    let mut a = Vec::new();
    let mut tau = Vec::new();
    let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
    for s in &scenario.srus {
        let d = model.evaluate(s.position, with_irs, &mut w);
        a.extend_from_slice(&w[..n]);
        a.push(d.h);
        tau.push(d.tau);
    }
    CellProblem { dim: n + 1, a, tau }
}

/// Certified gap (bit/s/Hz) within which a warm-started cell is kept without the cold search
/// (it is also kept when its gap is no more than 1 % above the previous cell's, where the
/// relaxation itself is loose). The paper map's median gap after the cold search is 2.5e-7;
/// with this rule its NOMA map keeps the warm answer in 79 % of the cells, is below the cold
/// search by at most 6e-6 bit/s/Hz in 7 % of them and above it in 2 % (docs/model.md §5).
pub const WARM_START_ACCEPT_GAP: f64 = 1e-6;

/// How much (bit/s/Hz) the certificate's lead must beat the `fast` answer by to replace it:
/// smaller differences are below what storing the phases as 16-bit codes moves a value
/// (about 10⁻¹⁰ either way on the paper's maps), so swapping would not raise the stored value.
pub const LEAD_MARGIN: f64 = 1e-9;

/// Certified gap (bit/s/Hz) within which a warm-started cell with K ≥ 2 SRUs is kept without
/// the cold search. The cold search cannot beat the upper bound, so a kept answer is below it
/// by at most this much: the values are the cold search's or better, to within what storing
/// the phases as 16-bit codes moves them (see [`LEAD_MARGIN`]). Elsewhere the cold search runs
/// too, the better answer is kept and the tighter of the two bounds; and the next cell starts
/// cold, because where the relaxation is loose a warm answer is seldom proved and would cost a
/// second certificate. K = 1 keeps a looser warm answer ([`WARM_START_ACCEPT_GAP`]): its
/// certificate does not depend on the answer, while the K ≥ 2 one costs more than the search.
pub const WARM_START_PROVEN_GAP: f64 = 1e-9;

/// What a map carries from one cell to the next along a grid row: where the `fast` solver's
/// family search ended in the last cell solved.
#[derive(Debug, Clone, Default)]
pub struct WarmStart {
    /// One point per (MRU, SRU) pair; empty after a cell left unserved.
    family: Vec<fast::FamilyPoint>,
    /// The certified gap of the last cell solved. K = 1: a warm answer whose gap is no larger
    /// is as good as its neighbour's, where the relaxation itself is not tight. K ≥ 2: above
    /// [`WARM_START_PROVEN_GAP`], the next cell starts cold.
    gap: f64,
}

/// Solves one cell with the chosen solver and phase mode, and certifies it.
pub fn solve_cell(
    problem: &CellProblem,
    model: &RateModel,
    phases: PhaseMode,
    solver: SolverKind,
) -> CellSolution {
    solve_cell_warm(problem, model, phases, solver, &mut WarmStart::default())
}

/// [`solve_cell`] warm-started from the previous cell of a map (`warm`, updated for the next).
/// The certificate comes first: a cell it proves infeasible needs no search, and the `fast`
/// solver's warm start is kept only when the certificate shows it good enough
/// ([`WARM_START_ACCEPT_GAP`] with one SRU, [`WARM_START_PROVEN_GAP`] with more); otherwise
/// the cold search runs as well and the better answer wins.
pub fn solve_cell_warm(
    problem: &CellProblem,
    model: &RateModel,
    phases: PhaseMode,
    solver: SolverKind,
    warm: &mut WarmStart,
) -> CellSolution {
    let mut lambdas = vec![0.0; problem.users()];
    let mut rate_of = |v: &[C64]| {
        problem.lambdas(v, &mut lambdas);
        objective(model, &lambdas)
    };
    if problem.dim == 1 {
        // No IRS: the gains are fixed; only the power split and order remain.
        let v = vec![C64::new(1.0, 0.0)];
        let rate = rate_of(&v);
        return CellSolution {
            v,
            rate,
            upper_bound: rate,
        };
    }
    let infeasible = || CellSolution {
        v: vec![C64::new(1.0, 0.0); problem.dim],
        rate: f64::NEG_INFINITY,
        upper_bound: f64::NEG_INFINITY,
    };
    // Not even the relaxation serves every SRU: no phase vector can, and no search is needed.
    // The K = 1 bound needs no primal, so it goes first; K ≥ 2 starts its dual from the primal.
    if !certificate::may_serve(problem, model) {
        return infeasible();
    }
    let early =
        (problem.users() == 2).then(|| certificate::certify(problem, model, None).upper_bound);
    if early == Some(f64::NEG_INFINITY) {
        return infeasible();
    }
    let (mut v, upper_bound) = match solver {
        SolverKind::Fast => {
            let mut hint = std::mem::take(&mut warm.family);
            if early.is_none() && warm.gap > WARM_START_PROVEN_GAP {
                // K ≥ 2 next to a cell whose relaxation was loose: likely loose here too, so a
                // warm answer would not be proved and the cold search would follow, with a
                // second certificate (the dearest ones: up to 50 ms at K = 4). Cold alone.
                hint.clear();
            }
            // The search from `hint` ([] for cold) with its bound: K = 1's does not depend on
            // the answer, so it is the one computed above; K ≥ 2 certifies the answer.
            let mut search = |hint: &[fast::FamilyPoint]| match early {
                Some(bound) => {
                    let (v, points) = fast::solve_from(problem, model, hint);
                    let rate = rate_of(&v);
                    (v, points, rate, bound)
                }
                None => joint_search(problem, model, hint, &mut rate_of),
            };
            let (mut v, mut points, mut rate, mut upper_bound) = search(&hint);
            // K = 1 also keeps a warm answer as loose as its neighbour's, where the relaxation
            // itself is loose; K ≥ 2 keeps one only where it is proved optimal (see the consts).
            let keep = match early {
                Some(_) => WARM_START_ACCEPT_GAP.max(warm.gap * 1.01),
                None => WARM_START_PROVEN_GAP,
            };
            if !hint.is_empty() && upper_bound - rate > keep {
                let (cold, cold_points, cold_rate, cold_bound) = search(&[]);
                if cold_rate >= rate {
                    (v, points, rate) = (cold, cold_points, cold_rate);
                }
                upper_bound = upper_bound.min(cold_bound);
            }
            // Only a served cell hands on its z: an infinite gap would make the next cell
            // accept any warm answer.
            let gap = upper_bound - rate;
            (warm.family, warm.gap) = if gap.is_finite() {
                (points, gap)
            } else {
                (Vec::new(), 0.0)
            };
            (v, upper_bound)
        }
        #[cfg(feature = "sdp")]
        SolverKind::SdrSca => {
            let v = sdr_sca::solve(problem, model).v;
            let upper_bound =
                early.unwrap_or_else(|| certificate::certify(problem, model, Some(&v)).upper_bound);
            (v, upper_bound)
        }
        #[cfg(not(feature = "sdp"))]
        SolverKind::SdrSca => unreachable!("map keys reject sdr-sca where it is not available"),
    };
    if upper_bound == f64::NEG_INFINITY {
        debug_assert!(
            rate_of(&v) == f64::NEG_INFINITY,
            "a served cell cannot be proved unservable"
        );
        return infeasible();
    }
    if let PhaseMode::Bits(b) = phases {
        fast::discrete_ascent(problem, model, b, &mut v);
    }
    // A reflection coefficient has unit modulus exactly (β_n = 1, paper Section II-A).
    for x in v.iter_mut() {
        *x /= x.norm();
    }
    let rate = rate_of(&v);
    CellSolution {
        v,
        rate,
        upper_bound,
    }
}

/// K ≥ 2: the `fast` search from `hint` (see [`fast::solve_from`]) and the joint certificate
/// of its answer; where the certificate's lead (the rounded dual of its best order) polishes to
/// a better rate, that answer instead. Returns v, the pairs' family points, v's rate and the
/// upper bound.
fn joint_search(
    problem: &CellProblem,
    model: &RateModel,
    hint: &[fast::FamilyPoint],
    rate_of: &mut impl FnMut(&[C64]) -> f64,
) -> (Vec<C64>, Vec<fast::FamilyPoint>, f64, f64) {
    let (mut v, points) = fast::solve_from(problem, model, hint);
    let mut rate = rate_of(&v);
    let certified = certificate::certify(problem, model, Some(&v));
    if let Some(mut lead) = certified.lead
        && certified.upper_bound - rate > WARM_START_ACCEPT_GAP
    {
        fast::polish(problem, model, &mut lead);
        let lead_rate = rate_of(&lead);
        if lead_rate > rate + LEAD_MARGIN {
            (v, rate) = (lead, lead_rate);
        }
    }
    (v, points, rate, certified.upper_bound)
}

/// θ_n = ∠v_n in [0, 2π) for n < N.
pub fn phases_of(v: &[C64]) -> impl Iterator<Item = f64> + '_ {
    v[..v.len() - 1].iter().map(|x| x.arg().rem_euclid(TAU))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solver_names_round_trip() {
        for solver in [SolverKind::Fast, SolverKind::SdrSca] {
            assert_eq!(solver.to_string().parse::<SolverKind>(), Ok(solver));
        }
        assert!(SolverKind::Fast.is_available());
        assert_eq!(SolverKind::SdrSca.is_available(), cfg!(feature = "sdp"));
    }
}
