//! Rate maps (docs/model.md §4–5): every free cell solved by the chosen solver and certified
//! by the SDR bound, in parallel over grid rows; the per-cell argmax (phases, power split,
//! decoding order) is kept because a path answer returns it at each waypoint.

use super::{Cancelled, CellConfig, MapKey, Progress};
use crate::channel::ChannelModel;
use crate::phases::{PhaseMode, decode_phase, encode_phase};
use crate::rate::{Access, RateModel};
use crate::scenario::{Grid, Scenario};
use crate::solver::{SolverKind, WarmStart, cell_problem, phases_of, solve_cell_warm, sru_part};
use rayon::prelude::*;

/// Per-cell configurations and certificates of a rate map (the values live in the map).
#[derive(Debug, Clone)]
pub struct RateCells {
    /// Per cell (flat index i·ny + j): the SDR upper bound on the MRU's rate (bit/s/Hz, §5).
    pub upper_bound: Vec<f64>,
    /// N, phases per cell (0 for `none`).
    pub(super) subsurfaces: usize,
    /// N_s of each surface, to split a cell's phases per surface.
    pub(super) surface_lengths: Vec<usize>,
    /// N phase codes per cell ([`encode_phase`]: 2 bytes each, within 4.8 × 10⁻⁵ rad): at
    /// N = 60 a cell takes 153 bytes instead of 513, so the cache holds 3.4× more maps.
    pub(super) phases: Vec<u16>,
    pub(super) power_w: Vec<f64>,
    pub(super) order: Vec<u8>,
    pub(super) model: RateModel,
}

impl RateCells {
    /// The configuration achieving the rate at cell `index` (flat): phases decoded from their
    /// codes, the power split and, under NOMA, the decoding order.
    pub fn config(&self, index: usize) -> CellConfig {
        let users = self.model.users();
        let n = self.subsurfaces;
        CellConfig {
            ap: 0,
            phases: super::per_surface(
                &self.phases[index * n..(index + 1) * n]
                    .iter()
                    .map(|&code| decode_phase(code))
                    .collect::<Vec<_>>(),
                &self.surface_lengths,
            ),
            power_w: Some(self.power_w[index * users..(index + 1) * users].to_vec()),
            decoding_order: (self.model.access == Access::Noma)
                .then(|| self.model.order_labels(self.order[index] as usize)),
        }
    }

    /// Bytes held: the per-cell bounds, phases, powers and decoding orders.
    pub fn size_bytes(&self) -> usize {
        8 * (self.upper_bound.capacity() + self.power_w.capacity())
            + 2 * self.phases.capacity()
            + self.order.capacity()
            + self.surface_lengths.capacity() * 8
    }

    /// Index of the decoding order used at a cell (into [`RateModel::orders`]).
    pub fn order(&self, index: usize) -> usize {
        self.order[index] as usize
    }

    /// The users' fixed data the cells were solved with: P_max, σ², the SRUs' targets, the orders.
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

/// Builds every free cell of a rate map in parallel (rows of the grid on rayon's pool); returns
/// the map values and the per-cell solutions.
pub(super) fn build_rate_cells(
    scenario: &Scenario,
    channel: &ChannelModel,
    grid: &Grid,
    occupied: &[bool],
    key: &MapKey,
    progress: &Progress,
) -> Result<(Vec<f64>, RateCells), Cancelled> {
    let model = RateModel::for_scenario(
        scenario,
        key.access.expect("rate keys carry an access scheme"),
    );
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
    let mut phases = vec![0u16; cells * phase_stride];
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
            // Each row is solved in order, every cell warm-started from the last one solved.
            let mut warm = WarmStart::default();
            for j in 0..ny {
                if progress.is_cancelled() {
                    return Err(Cancelled);
                }
                let cell = grid.index(i, j);
                if occupied[cell] {
                    continue;
                }
                let [x, y] = grid.centre(i, j);
                let problem = cell_problem(channel, [x, y, height], &srus, with_irs);
                let sol = solve_cell_warm(&problem, &model, key.phases, solver, &mut warm);
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
                        *dst = encode_phase(p);
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
        surface_lengths: channel.surface_lengths(),
        phases,
        power_w: power,
        order,
        model,
    };
    Ok((values, cells))
}
