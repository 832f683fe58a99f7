//! Rate-map solvers (SPEC §2): per cell, the IRS phases θ that maximise the MRU's expected rate
//! while every SRU meets its own, with the power split and decoding order in closed form
//! ([`crate::rate`]).
//!
//! Per cell the problem only sees, for each user l, the vector a_l = [w̃_l; h̃_l] ∈ C^{N+1} and
//! the scattered power τ_l, because λ_l(θ) = |a_lᵀ v|² + τ_l with v = [θ; 1] (paper eq. 23).
//!
//! * [`fast`] (default): the stationary-point family of SPEC §2 searched and refined.
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
use crate::radiomap::{BuildError, CellConfig, MapKey, PhaseMode, Progress, SolverKind};
use crate::rate::RateModel;
use crate::scenario::{Grid, Scenario};
use rayon::prelude::*;
use std::f64::consts::TAU;

/// Whether this build can run the `sdr-sca` solver (cargo feature `sdp`).
pub const SDR_SCA_AVAILABLE: bool = cfg!(feature = "sdp");

/// One cell's rate problem: a_l and τ_l for every user (0 = MRU, then the SRUs).
#[derive(Debug, Clone)]
pub struct CellProblem {
    /// N + 1 (the last entry of each a_l is h̃_l, paired with v_{N+1} = 1).
    pub dim: usize,
    /// a_l stacked: user l occupies `a[l·dim .. (l+1)·dim]`.
    pub a: Vec<C64>,
    pub tau: Vec<f64>,
}

impl CellProblem {
    pub fn users(&self) -> usize {
        self.tau.len()
    }
    pub fn user(&self, l: usize) -> &[C64] {
        &self.a[l * self.dim..(l + 1) * self.dim]
    }
    /// User l's own best gain over all phases, ‖a_l‖₁² + τ_l (eq. 15 for that user alone): an
    /// upper bound on λ_l that the relaxation attains, since a_l a_lᴴ has rank one.
    pub fn max_gain(&self, l: usize) -> f64 {
        self.user(l).iter().map(|x| x.norm()).sum::<f64>().powi(2) + self.tau[l]
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
/// served. Allocation-free: the inner objective of every solver.
#[inline]
pub fn objective(model: &RateModel, lambdas: &[f64]) -> f64 {
    (0..model.orders().len())
        .filter_map(|k| model.mru_rate(lambdas, k))
        .fold(f64::NEG_INFINITY, f64::max)
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

/// Per-cell configurations and certificates of a rate map (the values live in the map).
#[derive(Debug, Clone)]
pub struct RateCells {
    pub upper_bound: Vec<f64>,
    /// N, phases per cell (0 for `none`).
    subsurfaces: usize,
    phases: Vec<f64>,
    power_w: Vec<f64>,
    order: Vec<u8>,
    model: RateModel,
}

impl RateCells {
    pub fn config(&self, index: usize) -> CellConfig {
        let users = self.model.users();
        let n = self.subsurfaces;
        CellConfig {
            irs_phases_rad: self.phases[index * n..(index + 1) * n].to_vec(),
            power_w: Some(self.power_w[index * users..(index + 1) * users].to_vec()),
            decoding_order: (self.model.access == crate::radiomap::Access::Noma)
                .then(|| self.model.order_labels(self.order[index] as usize)),
        }
    }

    pub fn size_bytes(&self) -> usize {
        8 * (self.upper_bound.len() + self.phases.len() + self.power_w.len()) + self.order.len()
    }

    /// Index of the decoding order used at a cell (into [`RateModel::orders`]).
    pub fn order(&self, index: usize) -> usize {
        self.order[index] as usize
    }

    pub fn rate_model(&self) -> &RateModel {
        &self.model
    }

    /// Gaps upper_bound − achieved (`values`, the map's) over the cells where both are finite.
    pub fn gaps(&self, values: &[f64]) -> Vec<f64> {
        values
            .iter()
            .zip(&self.upper_bound)
            .filter(|(v, u)| v.is_finite() && u.is_finite())
            .map(|(v, u)| u - v)
            .collect()
    }
}

/// Builds the rate model of a scenario for a map key.
pub fn rate_model(scenario: &Scenario, key: &MapKey) -> RateModel {
    let targets: Vec<f64> = scenario.srus.iter().map(|s| s.min_rate_bps_hz).collect();
    RateModel::new(
        key.access.expect("rate keys carry an access scheme"),
        dbm_to_watts(scenario.ap.tx_power_dbm),
        dbm_to_watts(scenario.ap.noise_dbm),
        &targets,
    )
}

pub fn dbm_to_watts(dbm: f64) -> f64 {
    10f64.powf((dbm - 30.0) / 10.0)
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

/// Solves one cell with the chosen solver and phase mode, and certifies it.
pub fn solve_cell(
    problem: &CellProblem,
    model: &RateModel,
    phases: PhaseMode,
    solver: SolverKind,
) -> CellSolution {
    let mut lambdas = vec![0.0; problem.users()];
    if problem.dim == 1 {
        // No IRS: the gains are fixed; only the power split and order remain.
        let v = vec![C64::new(1.0, 0.0)];
        problem.lambdas(&v, &mut lambdas);
        let rate = objective(model, &lambdas);
        return CellSolution {
            v,
            rate,
            upper_bound: rate,
        };
    }
    let mut v = match solver {
        SolverKind::Fast => fast::solve(problem, model),
        #[cfg(feature = "sdp")]
        SolverKind::SdrSca => sdr_sca::solve(problem, model).v,
        #[cfg(not(feature = "sdp"))]
        SolverKind::SdrSca => unreachable!("MapKey::new rejects sdr-sca without the sdp feature"),
    };
    if let PhaseMode::Bits(b) = phases {
        fast::discrete_ascent(problem, model, b, &mut v);
    }
    // A reflection coefficient has unit modulus exactly (β_n = 1, paper Section II-A).
    for x in v.iter_mut() {
        *x /= x.norm();
    }
    problem.lambdas(&v, &mut lambdas);
    let rate = objective(model, &lambdas);
    let upper_bound = certificate::upper_bound(problem, model);
    CellSolution {
        v,
        rate,
        upper_bound,
    }
}

/// θ_n = ∠v_n in [0, 2π) for n < N.
pub fn phases_of(v: &[C64]) -> impl Iterator<Item = f64> + '_ {
    v[..v.len() - 1].iter().map(|x| x.arg().rem_euclid(TAU))
}

/// Builds every free cell of a rate map in parallel (rows of the grid on rayon's pool); returns
/// the map values and the per-cell solutions.
pub fn build_rate_cells(
    scenario: &Scenario,
    channel: &ChannelModel,
    grid: &Grid,
    occupied: &[bool],
    key: &MapKey,
    progress: &Progress,
) -> Result<(Vec<f64>, RateCells), BuildError> {
    let model = rate_model(scenario, key);
    let solver = key.solver.unwrap_or(SolverKind::Fast);
    let with_irs = key.phases != PhaseMode::None;
    let n = if with_irs { channel.subsurfaces() } else { 0 };
    let users = model.users();
    let srus = sru_part(channel, scenario, with_irs);
    let height = scenario.mru.antenna_height_m;
    let cells = grid.cells();
    let mut values = vec![f64::NAN; cells];
    let mut upper = vec![f64::NAN; cells];
    // One phase slot per cell even without IRS, so every row gets a (possibly unused) chunk.
    let phase_stride = n.max(1);
    let mut phases = vec![0.0; cells * phase_stride];
    let mut power = vec![0.0; cells * users];
    let mut order = vec![0u8; cells];
    let ny = grid.ny;
    values
        .par_chunks_mut(ny)
        .zip(upper.par_chunks_mut(ny))
        .zip(phases.par_chunks_mut(ny * phase_stride))
        .zip(power.par_chunks_mut(ny * users))
        .zip(order.par_chunks_mut(ny))
        .enumerate()
        .try_for_each(|(i, ((((vals, ups), ph), pw), ord))| {
            for j in 0..ny {
                if progress.is_cancelled() {
                    return Err(BuildError::Cancelled);
                }
                let cell = grid.index(i, j);
                if occupied[cell] {
                    continue;
                }
                let [x, y] = grid.centre(i, j);
                let problem = cell_problem(channel, [x, y, height], &srus, with_irs);
                let sol = solve_cell(&problem, &model, key.phases, solver);
                if sol.upper_bound.is_finite() {
                    ups[j] = sol.upper_bound;
                }
                if sol.rate.is_finite() {
                    vals[j] = sol.rate;
                    let mut lambdas = vec![0.0; users];
                    problem.lambdas(&sol.v, &mut lambdas);
                    let split = model.best(&lambdas).expect("a finite rate has a split");
                    pw[j * users..(j + 1) * users].copy_from_slice(&split.power_w);
                    ord[j] = split.order;
                    for (dst, p) in ph[j * n..(j + 1) * n].iter_mut().zip(phases_of(&sol.v)) {
                        *dst = p;
                    }
                }
                progress.advance(1);
            }
            // Occupied cells count as done too, so progress reaches the total.
            let occupied_in_row = (0..ny).filter(|&j| occupied[grid.index(i, j)]).count();
            progress.advance(occupied_in_row);
            Ok(())
        })?;
    phases.truncate(cells * n);
    let cells = RateCells {
        upper_bound: upper,
        subsurfaces: n,
        phases,
        power_w: power,
        order,
        model,
    };
    Ok((values, cells))
}
