//! Rate maps (docs/model.md §4–5): every free cell solved by the chosen solver and certified
//! by the SDR bound, in parallel over grid rows; the per-cell argmax (phases, power split,
//! decoding order) is kept because a path answer returns it at each waypoint.

use super::{Cancelled, CellConfig, MapKey, Progress};
use crate::channel::{C64, ChannelModel};
use crate::phases::{PhaseMode, decode_phase, encode_phase};
use crate::rate::{Access, PowerSplit, RateModel};
use crate::scenario::{Grid, Scenario};
use crate::solver::{
    CellProblem, SolverKind, WarmStart, cell_problem, phases_of, solve_cell_warm, sru_part,
};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::sync::Mutex;

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
                self.phases[index * n..(index + 1) * n]
                    .iter()
                    .map(|&code| decode_phase(code))
                    .collect(),
                self.surface_lengths.iter().copied(),
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

/// `v` of the coded phases: e^{jθ_n} of each decoded code, then v_{N+1} = 1.
fn decoded(codes: &[u16], v: &mut Vec<C64>) {
    v.clear();
    v.extend(codes.iter().map(|&c| C64::from_polar(1.0, decode_phase(c))));
    v.push(C64::new(1.0, 0.0));
}

/// What a rate map's cells give at phases other than the stored ones (a path answer's phases as
/// written, rounded to fewer decimals): the channel and the SRUs' part of the cell problems,
/// worked out once per map ([`super::RadioMap::rate_evaluator`]).
pub struct RateEvaluator<'a> {
    channel: ChannelModel,
    srus: CellProblem,
    with_irs: bool,
    height: f64,
    grid: &'a Grid,
    cells: &'a RateCells,
}

impl RateEvaluator<'_> {
    pub(super) fn new<'a>(
        scenario: &Scenario,
        key: &MapKey,
        grid: &'a Grid,
        cells: &'a RateCells,
    ) -> RateEvaluator<'a> {
        let channel = ChannelModel::new(scenario);
        let with_irs = key.phases != PhaseMode::None;
        let srus = sru_part(&channel, scenario, with_irs);
        RateEvaluator {
            channel,
            srus,
            with_irs,
            height: scenario.mru.antenna_height_m,
            grid,
            cells,
        }
    }

    /// Every user's expected gain λ_l (linear, MRU first) at the centre of cell `index` with
    /// the phases `theta` (all surfaces' in scenario order, radians).
    pub fn gains(&self, index: usize, theta: &[f64]) -> Vec<f64> {
        let (i, j) = self.grid.cell_of(index);
        let [x, y] = self.grid.centre(i, j);
        let problem = cell_problem(
            &self.channel,
            [x, y, self.height],
            &self.srus,
            self.with_irs,
        );
        let mut v: Vec<C64> = theta.iter().map(|&t| C64::from_polar(1.0, t)).collect();
        v.push(C64::new(1.0, 0.0));
        let mut lambdas = vec![0.0; self.cells.model.users()];
        problem.lambdas(&v, &mut lambdas);
        lambdas
    }

    /// The power split of the cell's own decoding order (OMA: the one split) at cell `index`
    /// with the phases `theta`, and the MRU's rate with it; `None` when it serves not every
    /// SRU there (or, NOMA, the gains break that order's channel ordering).
    pub fn split(&self, index: usize, theta: &[f64]) -> Option<PowerSplit> {
        let order = self.cells.order(index);
        self.cells.model.split(&self.gains(index, theta), order)
    }

    /// The users' fixed data: the rates and orders the splits are of.
    pub fn rate_model(&self) -> &RateModel {
        &self.cells.model
    }
}

/// One solved grid row of a rate map, as a checkpoint keeps it: everything the build writes
/// for the row's cells, in the layout of [`RateCells`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RateRow {
    /// The row's index i along x.
    pub row: u32,
    /// ny values (NaN where occupied or unserviceable).
    pub values: Vec<f64>,
    /// ny upper bounds.
    pub upper_bound: Vec<f64>,
    /// ny × max(N, 1) phase codes.
    pub phases: Vec<u16>,
    /// ny × users powers (W).
    pub power_w: Vec<f64>,
    /// ny decoding-order indices.
    pub order: Vec<u8>,
}

/// The rows of one rate-map build solved so far, shared between the build and whoever keeps
/// its checkpoints: the rows an interrupted build had solved (copied, not solved again) and,
/// when recording, the rows this build solves, to be taken as they come
/// ([`Checkpoint::take_solved`]). Rows only: a row is solved in order on one worker, so a row
/// in progress when the build stops is solved again, never half-kept.
#[derive(Debug, Default)]
pub struct Checkpoint {
    resumed: HashMap<u32, RateRow>,
    recording: bool,
    solved: Mutex<Vec<RateRow>>,
}

impl Checkpoint {
    /// A checkpoint that records the rows solved, resuming from `rows` (rows of the same map
    /// key; a row whose lengths do not fit the grid is solved again).
    pub fn recording(rows: Vec<RateRow>) -> Checkpoint {
        Checkpoint {
            resumed: rows.into_iter().map(|r| (r.row, r)).collect(),
            recording: true,
            solved: Mutex::default(),
        }
    }

    /// The rows given to resume from.
    pub fn resumed_rows(&self) -> usize {
        self.resumed.len()
    }

    /// The rows solved since the last call (none unless recording).
    pub fn take_solved(&self) -> Vec<RateRow> {
        std::mem::take(&mut *self.solved.lock().expect("checkpoint rows"))
    }

    /// Every row it holds, by row: those it resumed from and those solved since the last
    /// [`Checkpoint::take_solved`] (a checkpoint saved whole, not appended to).
    pub fn all_rows(&self) -> Vec<RateRow> {
        let mut rows: Vec<RateRow> = self.resumed.values().cloned().collect();
        rows.extend(self.take_solved());
        rows.sort_by_key(|r| r.row);
        rows.dedup_by_key(|r| r.row);
        rows
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
    checkpoint: &Checkpoint,
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
            if let Some(row) = checkpoint.resumed.get(&(i as u32))
                && row.values.len() == vals.len()
                && row.upper_bound.len() == ups.len()
                && row.phases.len() == ph.len()
                && row.power_w.len() == pw.len()
                && row.order.len() == ord.len()
            {
                vals.copy_from_slice(&row.values);
                ups.copy_from_slice(&row.upper_bound);
                ph.copy_from_slice(&row.phases);
                pw.copy_from_slice(&row.power_w);
                ord.copy_from_slice(&row.order);
                progress.advance(ny);
                return Ok(());
            }
            // Each row is solved in order, every cell warm-started from the last one solved.
            let mut warm = WarmStart::default();
            let (mut lambdas, mut coded) = (vec![0.0; users], Vec::with_capacity(n + 1));
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
                    // The phases are kept, and sent, as 16-bit codes: the split, the order and
                    // the value are those of the coded phases, so that a waypoint's numbers
                    // reproduce each other (docs/model.md §5). A cell the coded phases cannot
                    // serve (an SRU within about 10⁻⁶ bit/s/Hz of its target) stays unserved.
                    let codes = &mut ph[j * n..(j + 1) * n];
                    for (dst, p) in codes.iter_mut().zip(phases_of(&sol.v)) {
                        *dst = encode_phase(p);
                    }
                    decoded(codes, &mut coded);
                    problem.lambdas(&coded, &mut lambdas);
                    match model.best(&lambdas) {
                        Some(split) => {
                            vals[j] = split.mru_rate;
                            pw[j * users..(j + 1) * users].copy_from_slice(&split.power_w);
                            ord[j] = split.order;
                        }
                        None => codes.fill(0),
                    }
                }
                progress.advance(1);
            }
            // Occupied cells count as done too, so progress reaches the total.
            let occupied_in_row = (0..ny).filter(|&j| occupied[grid.index(i, j)]).count();
            progress.advance(occupied_in_row);
            if checkpoint.recording {
                let row = RateRow {
                    row: i as u32,
                    values: vals.to_vec(),
                    upper_bound: ups.to_vec(),
                    phases: ph.to_vec(),
                    power_w: pw.to_vec(),
                    order: ord.to_vec(),
                };
                checkpoint.solved.lock().expect("checkpoint rows").push(row);
            }
            Ok(())
        })?;
    phases.truncate(cells * n);
    let cells = RateCells {
        upper_bound: upper,
        subsurfaces: n,
        surface_lengths: channel.surface_lengths().collect(),
        phases,
        power_w: power,
        order,
        model,
    };
    Ok((values, cells))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radiomap::{CellSolutions, RadioMap, build, build_resuming};
    use crate::rate::Access;

    fn rate_cells(map: &RadioMap) -> &RateCells {
        match &map.cells {
            CellSolutions::Rate(r) => r,
            CellSolutions::Gain { .. } => panic!("a rate map"),
        }
    }

    fn bits(values: &[f64]) -> Vec<u64> {
        values.iter().map(|v| v.to_bits()).collect()
    }

    /// Every served cell's value, power split and decoding order are those of its phases as
    /// stored: re-evaluated from the decoded codes, each SRU gets its r̄ and the MRU the
    /// cell's value, to 1e-9 (paper multi-user floor at 1 m with a second SRU, OMA and NOMA).
    #[test]
    fn a_cell_reproduces_its_value_from_its_stored_phases_powers_and_order() {
        let s = Scenario::builtin_with("paper-multi-user", |v| {
            v["grid"]["resolution_m"] = 1.0.into();
            v["srus"]
                .as_array_mut()
                .unwrap()
                .push(serde_json::json!({"position": [-6.0, 7.0, 1.3], "min_rate_bps_hz": 0.5}));
        })
        .unwrap()
        .unwrap();
        for access in [Access::Oma, Access::Noma] {
            let key = MapKey::rate("test", &s, PhaseMode::Continuous, access).unwrap();
            let map = build(&s, &key, "m".into(), &Progress::default()).unwrap();
            let cells = rate_cells(&map);
            let evaluator = map.rate_evaluator(&s).unwrap();
            let model = evaluator.rate_model();
            let mut served = 0;
            for index in 0..map.values.len() {
                if !map.values[index].is_finite() {
                    continue;
                }
                served += 1;
                let config = map.cell_config(index);
                let theta = config.concatenated_phases();
                let power = config.power_w.unwrap();
                let rates =
                    model.rates(&evaluator.gains(index, &theta), &power, cells.order(index));
                assert!(
                    (rates[0] - map.values[index]).abs() < 1e-9,
                    "{access:?} cell {index}: {} vs {}",
                    rates[0],
                    map.values[index]
                );
                for (l, (&r, &target)) in rates.iter().zip(model.targets()).enumerate().skip(1) {
                    assert!(
                        r >= target - 1e-9,
                        "{access:?} cell {index}: SRU {l} gets {r} < {target}"
                    );
                }
                assert!(cells.upper_bound[index] >= map.values[index] - 1e-9);
            }
            assert!(served > 300, "{served} cells served");
        }
    }

    /// A build resumed from some rows of an earlier one copies those rows (a marked value
    /// comes through), solves the others (a row that does not fit the grid among them) to the
    /// same bits as an uninterrupted build, counts every cell in its progress, and records
    /// only the rows it solved.
    #[test]
    fn a_resumed_build_copies_its_rows_and_solves_the_rest_identically() {
        let s = Scenario::builtin("small-test").unwrap();
        let key = MapKey::rate("test", &s, PhaseMode::Continuous, Access::Noma).unwrap();
        let recorder = Checkpoint::recording(Vec::new());
        let whole = build_resuming(&s, &key, "m".into(), &Progress::default(), &recorder).unwrap();
        let mut rows = recorder.take_solved();
        assert_eq!(rows.len(), whole.grid.nx, "every row recorded once");
        assert!(recorder.take_solved().is_empty(), "taken rows are gone");
        rows.sort_by_key(|r| r.row);
        let plain = build(&s, &key, "m".into(), &Progress::default()).unwrap();
        assert_eq!(
            bits(&plain.values),
            bits(&whole.values),
            "recording changes nothing"
        );

        // Even rows resume; row 2's value at a free cell is marked; row 4 is cut short.
        let mut kept: Vec<RateRow> = rows.iter().filter(|r| r.row % 2 == 0).cloned().collect();
        let free = kept[1].values.iter().position(|v| v.is_finite()).unwrap();
        kept[1].values[free] = 123.0;
        kept[2].values.pop();
        let resumed_rows = kept.len();
        let progress = Progress::default();
        let resumer = Checkpoint::recording(kept);
        let resumed = build_resuming(&s, &key, "m".into(), &progress, &resumer).unwrap();
        assert_eq!(resumer.resumed_rows(), resumed_rows);
        assert_eq!(progress.cells_done(), progress.cells_total());
        let ny = whole.grid.ny;
        let marked = 2 * ny + free;
        assert_eq!(
            resumed.values[marked], 123.0,
            "row 2 was copied, not solved"
        );
        let mut expected = bits(&whole.values);
        expected[marked] = 123f64.to_bits();
        assert_eq!(bits(&resumed.values), expected);
        let (a, b) = (rate_cells(&whole), rate_cells(&resumed));
        assert_eq!(bits(&a.upper_bound), bits(&b.upper_bound));
        assert_eq!(a.phases, b.phases);
        assert_eq!(bits(&a.power_w), bits(&b.power_w));
        assert_eq!(a.order, b.order);
        let mut solved: Vec<u32> = resumer.take_solved().iter().map(|r| r.row).collect();
        solved.sort_unstable();
        let expected: Vec<u32> = (0..whole.grid.nx as u32)
            .filter(|i| i % 2 == 1 || *i == 4)
            .collect();
        assert_eq!(
            solved, expected,
            "only the odd rows and the row that did not fit"
        );
    }
}
