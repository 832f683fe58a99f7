//! The paper's reference solver (Algorithms 1 and 2) on Clarabel: for every decoding order,
//! bisection on the MRU's rate target r; each target is checked by the semidefinite relaxation
//! (problem 29 without eq. 29g) and, when that is feasible, by SCA on the rank penalty
//! ‖V‖_* − ‖V‖₂ (eqs. 34–36): since ‖V‖_* = tr V = N+1 on the feasible set, each SCA step
//! maximises u_maxᴴ V u_max, the linearisation of ‖V‖₂ at the previous iterate.
//!
//! The rate constraints are the unrolled closed form of [`crate::rate`]: Σ_l c_l(r)/λ_l(V) ≤ P,
//! written with epigraph variables t_l ≥ c_l/λ_l(V) as rotated second-order cones
//! ((t_l + λ_l)/2 ≥ ‖((t_l − λ_l)/2, √c_l)‖), which is the paper's eqs. 29b–c (via 30–31) with the
//! power split eliminated. The SIC ordering (eq. 29d) is linear in V.
//!
//! Clarabel has no complex PSD cone, so V = V_r + jV_i ⪰ 0 is embedded as the real
//! X = [[V_r, −V_i], [V_i, V_r]] ⪰ 0; the variables are the strict upper triangles of V_r and
//! V_i (diag V = 1 is fixed, eq. 29e). A target is declared feasible when an extracted rank-one
//! v (principal eigenvector, projected to unit modulus) reaches it in the exact objective.

use super::{CellProblem, objective};
use crate::channel::C64;
use crate::rate::RateModel;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
    SupportedConeT::{NonnegativeConeT, PSDTriangleConeT, SecondOrderConeT},
};
use nalgebra::{DMatrix, SymmetricEigen};

/// Bisection accuracy ε₀ (bit/s/Hz).
const BISECTION_TOLERANCE: f64 = 1e-4;
const MAX_SCA_ITERATIONS: usize = 25;

/// Result of the SDR+SCA solver.
pub struct SdrScaSolution {
    /// v = [e^{jθ}; 1].
    pub v: Vec<C64>,
    /// The relaxation's own value (the SDR bound from the bisection), −∞ if infeasible.
    pub relaxed_rate: f64,
}

/// Solves one cell (§5, `sdr-sca`): per decoding order, bisection on the MRU's rate target,
/// each target checked by the SDR and then SCA; returns the best v (θ = 0 unless SCA beats it).
pub fn solve(problem: &CellProblem, model: &RateModel) -> SdrScaSolution {
    let dim = problem.dim;
    let mut best_v = vec![C64::new(1.0, 0.0); dim];
    let mut lambdas = vec![0.0; problem.users()];
    problem.lambdas(&best_v, &mut lambdas);
    let mut best = objective(model, &lambdas);
    let mut relaxed_rate = f64::NEG_INFINITY;
    let upper = super::certificate::certify(problem, model, None).upper_bound;
    if !upper.is_finite() {
        return SdrScaSolution {
            v: best_v,
            relaxed_rate,
        };
    }
    for order in 0..model.orders().len() {
        let sdp = Sdp::new(problem, model, order);
        // The relaxation at r = 0: if it cannot serve the SRUs, no phase vector can.
        let Some(_) = sdp.solve(0.0, None) else {
            continue;
        };
        let (mut lo, mut hi) = (0.0, upper + 1e-3);
        let mut relaxed_lo = 0.0;
        while hi - lo > BISECTION_TOLERANCE {
            let r = 0.5 * (lo + hi);
            let Some(v0) = sdp.solve(r, None) else {
                hi = r;
                continue;
            };
            relaxed_lo = r;
            match sdp.sca(r, v0) {
                Some(v) => {
                    problem.lambdas(&v, &mut lambdas);
                    let achieved = model.mru_rate(&lambdas, order).unwrap_or(f64::NEG_INFINITY);
                    if achieved > best {
                        best = achieved;
                        best_v = v;
                    }
                    lo = r.max(achieved.min(hi));
                    // The rank-one point reaching `achieved` is feasible in the relaxation too.
                    relaxed_lo = lo;
                }
                None => hi = r,
            }
        }
        relaxed_rate = relaxed_rate.max(relaxed_lo);
    }
    SdrScaSolution {
        v: best_v,
        relaxed_rate,
    }
}

/// The relaxed feasibility problem of one decoding order, ready to be solved for any target.
struct Sdp<'a> {
    problem: &'a CellProblem,
    model: &'a RateModel,
    order: usize,
    /// λ_l = λ0_l + g_l · x (scaled by `scale`), x = (V_r upper, V_i upper).
    lambda0: Vec<f64>,
    grad: Vec<Vec<f64>>,
    scale: f64,
}

impl<'a> Sdp<'a> {
    fn new(problem: &'a CellProblem, model: &'a RateModel, order: usize) -> Self {
        let n = problem.dim;
        let pairs = n * (n - 1) / 2;
        let scale = (0..problem.users())
            .map(|l| problem.max_gain(l))
            .fold(0.0, f64::max);
        let mut lambda0 = Vec::new();
        let mut grad = Vec::new();
        for l in 0..problem.users() {
            let a = problem.user(l);
            lambda0.push((a.iter().map(|x| x.norm_sqr()).sum::<f64>() + problem.tau[l]) / scale);
            // λ = Σ_ij a_i conj(a_j) V_ij = Σ|a_i|² + 2 Σ_{i<j} (Re B_ij V_r,ij − Im B_ij V_i,ij).
            let mut g = vec![0.0; 2 * pairs];
            for (p, (i, j)) in upper_pairs(n).enumerate() {
                let b = a[i] * a[j].conj();
                g[p] = 2.0 * b.re / scale;
                g[pairs + p] = -2.0 * b.im / scale;
            }
            grad.push(g);
        }
        Sdp {
            problem,
            model,
            order,
            lambda0,
            grad,
            scale,
        }
    }

    /// Solves the relaxation at target r: maximising uᴴVu when `u` is given (an SCA step),
    /// finding any feasible point otherwise. Returns V, or `None` if the target is infeasible.
    fn solve(&self, r: f64, u: Option<&[C64]>) -> Option<DMatrix<C64>> {
        let n = self.problem.dim;
        let pairs = n * (n - 1) / 2;
        let mut q = vec![0.0; 2 * pairs + self.problem.users()];
        if let Some(u) = u {
            // −uᴴVu = −Σ|u_i|² − 2 Σ_{i<j} (Re w_ij V_r,ij − Im w_ij V_i,ij), w_ij = conj(u_i) u_j.
            for (p, (i, j)) in upper_pairs(n).enumerate() {
                let w = u[i].conj() * u[j];
                q[p] = -2.0 * w.re;
                q[pairs + p] = 2.0 * w.im;
            }
        }
        self.solve_with_objective(r, q)
    }

    /// The relaxation at target r, minimising qᵀx.
    fn solve_with_objective(&self, r: f64, q: Vec<f64>) -> Option<DMatrix<C64>> {
        let n = self.problem.dim;
        let pairs = n * (n - 1) / 2;
        let users = self.problem.users();
        let vars = 2 * pairs + users;
        let mut columns: Vec<Vec<(usize, f64)>> = vec![Vec::new(); vars];
        let mut b = Vec::new();
        let mut cones: Vec<SupportedConeT<f64>> = Vec::new();
        let mut row = 0usize;
        // Rotated SOC per user: t_l λ_l ≥ c_l, with t in units of P_max and λ in units of `scale`.
        for l in 0..users {
            let mut unit = vec![f64::INFINITY; users];
            unit[l] = 1.0;
            let c =
                self.model.required_power(&unit, self.order, r) / (self.model.p_max_w * self.scale);
            let t = 2 * pairs + l;
            // s0 = (t + λ)/2, s1 = (t − λ)/2, s2 = √c.
            b.push(self.lambda0[l] / 2.0);
            columns[t].push((row, -0.5));
            b.push(-self.lambda0[l] / 2.0);
            columns[t].push((row + 1, -0.5));
            for (k, g) in self.grad[l].iter().enumerate() {
                if *g != 0.0 {
                    columns[k].push((row, -g / 2.0));
                    columns[k].push((row + 1, g / 2.0));
                }
            }
            b.push(c.max(0.0).sqrt());
            row += 3;
            cones.push(SecondOrderConeT(3));
        }
        // Σ t_l ≤ 1 and the SIC ordering λ_{π[k]} ≤ λ_{π[k+1]}.
        let mut nonneg = 1;
        b.push(1.0);
        for l in 0..users {
            columns[2 * pairs + l].push((row, 1.0));
        }
        row += 1;
        if self.model.access == crate::rate::Access::Noma {
            for w in self.model.orders()[self.order].windows(2) {
                let (weak, strong) = (w[0] as usize, w[1] as usize);
                b.push(self.lambda0[strong] - self.lambda0[weak]);
                for (column, (gs, gw)) in columns
                    .iter_mut()
                    .zip(self.grad[strong].iter().zip(&self.grad[weak]))
                {
                    let d = gs - gw;
                    if d != 0.0 {
                        column.push((row, -d));
                    }
                }
                row += 1;
                nonneg += 1;
            }
        }
        cones.push(NonnegativeConeT(nonneg));
        // X = [[V_r, −V_i], [V_i, V_r]] ⪰ 0 in Clarabel's svec (upper triangle by columns, √2
        // on off-diagonals).
        let sqrt2 = std::f64::consts::SQRT_2;
        let pair_index = |i: usize, j: usize| -> usize { j * (j - 1) / 2 + i }; // i < j
        for c in 0..2 * n {
            for r_ in 0..=c {
                let (bi, bj) = (r_ / n, c / n);
                let (i, j) = (r_ % n, c % n);
                match (bi, bj) {
                    (0, 0) | (1, 1) => {
                        if i == j {
                            b.push(1.0);
                        } else {
                            b.push(0.0);
                            let p = if i < j {
                                pair_index(i, j)
                            } else {
                                pair_index(j, i)
                            };
                            columns[p].push((row, -sqrt2));
                        }
                    }
                    _ => {
                        // Upper-right block: −V_i[i][j] with V_i antisymmetric.
                        b.push(0.0);
                        if i < j {
                            columns[pairs + pair_index(i, j)].push((row, sqrt2));
                        } else if i > j {
                            columns[pairs + pair_index(j, i)].push((row, -sqrt2));
                        }
                    }
                }
                row += 1;
            }
        }
        cones.push(PSDTriangleConeT(2 * n));
        let a = csc(row, columns);
        let zero = CscMatrix::zeros((vars, vars));
        let settings = DefaultSettingsBuilder::default()
            .verbose(false)
            .max_iter(200)
            .build()
            .ok()?;
        let mut solver = DefaultSolver::new(&zero, &q, &a, &b, &cones, settings).ok()?;
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {}
            _ => return None,
        }
        let x = &solver.solution.x;
        let mut v = DMatrix::from_element(n, n, C64::new(0.0, 0.0));
        for i in 0..n {
            v[(i, i)] = C64::new(1.0, 0.0);
        }
        for (p, (i, j)) in upper_pairs(n).enumerate() {
            let z = C64::new(x[p], x[pairs + p]);
            v[(i, j)] = z;
            v[(j, i)] = z.conj();
        }
        Some(v)
    }

    /// Algorithm 1 from the relaxed solution `v0`: SCA steps until V is rank one (the rank
    /// penalty N+1 − λ_max vanishes) or stalls; returns the extracted unit-modulus v if it meets
    /// the target r exactly.
    fn sca(&self, r: f64, mut matrix: DMatrix<C64>) -> Option<Vec<C64>> {
        let n = self.problem.dim;
        let mut last_penalty = f64::INFINITY;
        let mut lambdas = vec![0.0; self.problem.users()];
        for _ in 0..MAX_SCA_ITERATIONS {
            let eigen = SymmetricEigen::new(matrix.clone());
            let top =
                (0..n).max_by(|&p, &q| eigen.eigenvalues[p].total_cmp(&eigen.eigenvalues[q]))?;
            let u: Vec<C64> = eigen.eigenvectors.column(top).iter().copied().collect();
            let penalty = n as f64 - eigen.eigenvalues[top];
            // Rank-one extraction: unit-modulus projection, referenced to v_{N+1} = 1.
            let reference = u[n - 1].conj() / u[n - 1].norm().max(f64::MIN_POSITIVE);
            let v: Vec<C64> = u
                .iter()
                .map(|x| {
                    if x.norm() > 0.0 {
                        x * reference / x.norm()
                    } else {
                        C64::new(1.0, 0.0)
                    }
                })
                .collect();
            self.problem.lambdas(&v, &mut lambdas);
            if self
                .model
                .mru_rate(&lambdas, self.order)
                .is_some_and(|achieved| achieved >= r - 1e-12)
            {
                return Some(v);
            }
            if penalty < 1e-7 * n as f64 || last_penalty - penalty < 1e-9 * n as f64 {
                return None;
            }
            last_penalty = penalty;
            matrix = self.solve(r, Some(&u))?;
        }
        None
    }
}

fn upper_pairs(n: usize) -> impl Iterator<Item = (usize, usize)> {
    (1..n).flat_map(|j| (0..j).map(move |i| (i, j)))
}

fn csc(rows: usize, columns: Vec<Vec<(usize, f64)>>) -> CscMatrix<f64> {
    let mut colptr = vec![0];
    let mut rowval = Vec::new();
    let mut nzval = Vec::new();
    for mut col in columns.clone() {
        col.sort_by_key(|e| e.0);
        for (r, v) in col {
            rowval.push(r);
            nzval.push(v);
        }
        colptr.push(rowval.len());
    }
    CscMatrix::new(rows, columns.len(), colptr, rowval, nzval)
}

/// max{tr(W V) : V ⪰ 0, diag V = 1} for W = Σ_l w_l ā_l ā_lᴴ (one a-vector per user, all of
/// the same length), solved by Clarabel: the exact SDP value that the certificate's support
/// bounds ([`super::certificate::support_bound`] for two users, its joint form for more) bound
/// without a solver.
pub fn support_value(users: &[Vec<C64>], w: &[f64]) -> Option<f64> {
    let dim = users[0].len();
    let problem = CellProblem {
        dim,
        a: users.iter().flatten().copied().collect(),
        tau: vec![0.0; users.len()],
    };
    // OMA with zero targets makes every rate constraint vacuous: only V ⪰ 0, diag V = 1 bind.
    let model = RateModel::new(
        crate::rate::Access::Oma,
        1.0,
        1.0,
        &vec![0.0; users.len() - 1],
    );
    let sdp = Sdp::new(&problem, &model, 0);
    let pairs = dim * (dim - 1) / 2;
    let weights: Vec<f64> = (0..2 * pairs)
        .map(|k| (0..users.len()).map(|l| w[l] * sdp.grad[l][k]).sum())
        .collect();
    let mut q: Vec<f64> = weights.iter().map(|w| -w).collect();
    q.extend(vec![0.0; users.len()]);
    let matrix = sdp.solve_with_objective(0.0, q)?;
    let value: f64 = upper_pairs(dim)
        .enumerate()
        .map(|(p, (i, j))| weights[p] * matrix[(i, j)].re + weights[pairs + p] * matrix[(i, j)].im)
        .sum();
    let diagonal: f64 = (0..users.len()).map(|l| w[l] * sdp.lambda0[l]).sum();
    Some((diagonal + value) * sdp.scale)
}
