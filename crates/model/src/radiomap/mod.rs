//! Radio maps (docs/model.md §3–4): per free grid cell the best value the MRU can get there, and
//! the configuration that achieves it.
//!
//! * [`key`]: what defines a map ([`MapKey`]); its hash is the map id.
//! * [`gain`]: the channel power gain map C (eqs. 9 and 12), in dB.
//! * [`rate_cells`]: the communication rate map U (eqs. 26 and 37), in bit/s/Hz, solved per cell
//!   by [`crate::solver`].
//! * [`body`]: statistics, coverage and the certificate summary of a built map.
//!
//! Occupied cells hold NaN (JSON null, the paper's −∞).

pub mod body;
pub mod cost;
pub mod gain;
pub mod key;
mod parts;
pub mod passages;
pub mod rate_cells;
pub mod units;

pub use body::{CertificateSummary, MapStats};
pub use key::{MapKey, MapKind};
pub use parts::StoredCells;
pub use passages::{ClosedPassage, ClosedPassages};
pub use rate_cells::{Checkpoint, RateCells, RateEvaluator, RateRow};
pub use units::{LinkBudget, Unit};

use crate::channel::ChannelModel;
use crate::scenario::{Grid, Scenario};
use rayon::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Shared progress and cancellation of one piece of long work (a map build, a search, a query).
#[derive(Debug, Default)]
pub struct Progress {
    done: AtomicUsize,
    total: AtomicUsize,
    /// Shared with the [`Progress::child`]ren: a cancel reaches the work nested in this one.
    cancelled: Arc<AtomicBool>,
}

impl Progress {
    /// Units of work done so far: grid cells for a map build, waypoints for a check, thresholds
    /// for a sweep.
    pub fn cells_done(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }
    /// Units of work in all, as the last [`Progress::start`] set them (0 before it).
    pub fn cells_total(&self) -> usize {
        self.total.load(Ordering::Relaxed)
    }
    /// Asks the work to stop at its next check, where it returns [`Cancelled`].
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }
    /// True once [`Progress::cancel`] was called.
    pub fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
    /// The progress of a piece of this work that counts its own units (a placement candidate's
    /// map build) and stops when this one is cancelled.
    pub fn child(&self) -> Progress {
        Progress {
            cancelled: self.cancelled.clone(),
            ..Progress::default()
        }
    }
    /// Starts counting: `total` units of work, none done.
    pub fn start(&self, total: usize) {
        self.total.store(total, Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
    }
    /// Counts `cells` more units done.
    pub fn advance(&self, cells: usize) {
        self.done.fetch_add(cells, Ordering::Relaxed);
    }
}

/// A build stopped by [`Progress::cancel`]; the only way a build of a validated key can fail.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the work was cancelled")]
pub struct Cancelled;

/// Why long work (a placement search, a sweep) gave no answer: what it was asked is invalid,
/// or it was cancelled.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorkError {
    /// The request is invalid: the field at fault and why.
    #[error(transparent)]
    Invalid(#[from] crate::input::FieldError),
    /// The work was stopped through its [`Progress`].
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// What a map keeps per cell to answer "how do I configure the IRS (and the AP) here?".
#[derive(Debug, Clone)]
pub enum CellSolutions {
    /// Gain maps: θ* is recomputed per waypoint from the serving AP's channel model (see
    /// [`gain`]).
    Gain {
        /// One model per AP, in scenario order.
        models: Vec<Arc<ChannelModel>>,
        /// The AP serving each cell, the one received strongest (empty with one AP).
        serving: Vec<u8>,
        /// The serving AP's gain (dB) per cell, where that AP is not the one of best gain (a
        /// weaker channel from a stronger transmitter); empty when the AP of best gain serves
        /// every cell, always so with one AP or APs of one link budget.
        serving_gain_db: Vec<f64>,
        /// H₀ (m): the height of the MRU antenna, where a waypoint's θ* is recomputed.
        antenna_height_m: f64,
    },
    /// Rate maps: the solver's argmax per cell (phases, power split, order, certificate).
    Rate(RateCells),
}

/// The IRS phase vector θ of one configuration, one vector per IRS in scenario order (N_s
/// values each, in [0, 2π); none for phases `none`). Most scenarios have one IRS, so its
/// vector is held in place: each waypoint of a path holds one, and an outer vector of a single
/// element was an allocation and a free per waypoint (5 % of the time to write a 1 001-waypoint
/// body, bench `path_answer`).
pub type SurfaceRadians = smallvec::SmallVec<[Vec<f64>; 1]>;

/// The configuration to apply at one waypoint. `P` is how its phases are held: radians in the
/// model, the written form (decimals or codes) in an answer.
#[derive(Debug, Clone, PartialEq)]
pub struct CellConfig<P = SurfaceRadians> {
    /// The AP serving this cell (an index into the scenario's APs; 0 with one AP).
    pub ap: usize,
    /// The IRS phases, written as `irs_phases_rad` or `irs_phase_codes`.
    pub phases: P,
    /// Rate maps: transmit power per user (W), MRU first then the SRUs in scenario order
    /// (written only on them).
    pub power_w: Option<Vec<f64>>,
    /// NOMA rate maps: users in SIC decoding order (decoded first = weakest first; written only
    /// on them).
    pub decoding_order: Option<Vec<String>>,
}

/// A computed radio map.
#[derive(Debug, Clone)]
pub struct RadioMap {
    /// What defines the map (scenario id, kind, phase mode, access, solver, model version).
    pub key: MapKey,
    /// The map id (`irs_answers::map::map_id`: a hash of the key's document), given to
    /// [`build`] and kept: every path answer names it, and hashing the key was 3 % of a repeated
    /// path query's time.
    pub id: String,
    /// The scenario's grid the values are laid on.
    pub grid: Grid,
    /// Per cell (flat index i·ny + j): dB for gain maps, bit/s/Hz for rate maps, NaN if occupied
    /// (and, on rate maps, where no configuration meets every SRU's rate).
    pub values: Vec<f64>,
    /// Per cell: true if an obstacle, a wall or the floor plan overlaps its square (widened by
    /// the robot's radius; docs/model.md §1).
    pub occupied: Vec<bool>,
    /// The passages that occupancy closes (where the grid is too coarse for a gap).
    pub closed_passages: ClosedPassages,
    /// What answers "how do I configure the IRS here?" at each cell.
    pub cells: CellSolutions,
    /// Each AP's link budget, which turns gains into received power, SNR and throughput
    /// ([`RadioMap::values_in`]).
    pub links: Vec<LinkBudget>,
    /// Wall-clock build time (s).
    pub build_seconds: f64,
    /// When the build finished (seconds since the Unix epoch): exported files are dated by it,
    /// so the same map exports the same bytes on every replica and after every restart.
    pub built_at_unix_s: u64,
}

/// Splits a concatenated phase vector into the surfaces' vectors (lengths N_s in order). One
/// surface, the usual case, keeps `flat` itself: a path's waypoints each asked for a copy and
/// a list of lengths, three allocations where one does.
pub(crate) fn per_surface(
    flat: Vec<f64>,
    lengths: impl ExactSizeIterator<Item = usize>,
) -> SurfaceRadians {
    if flat.is_empty() {
        return SurfaceRadians::new();
    }
    if lengths.len() == 1 {
        return smallvec::smallvec![flat];
    }
    let mut rest = &flat[..];
    lengths
        .map(|n| {
            let (own, tail) = rest.split_at(n);
            rest = tail;
            own.to_vec()
        })
        .collect()
}

impl CellConfig {
    /// The phases of every surface concatenated (the vector θ the channel model takes).
    pub fn concatenated_phases(&self) -> Vec<f64> {
        self.phases.concat()
    }
}

impl<P> CellConfig<P> {
    /// The same configuration with its phases held as `f` makes them.
    pub fn map_phases<Q>(self, f: impl FnOnce(P) -> Q) -> CellConfig<Q> {
        CellConfig {
            ap: self.ap,
            phases: f(self.phases),
            power_w: self.power_w,
            decoding_order: self.decoding_order,
        }
    }
}

impl RadioMap {
    /// The AP serving cell `index` (what [`RadioMap::cell_config`] names, without working out
    /// the rest of the configuration).
    pub fn serving_ap(&self, index: usize) -> usize {
        match &self.cells {
            CellSolutions::Gain { serving, .. } => {
                serving.get(index).map_or(0, |&k| usize::from(k))
            }
            CellSolutions::Rate(_) => 0,
        }
    }

    /// The configuration to apply at cell `index`: on a rate map the one achieving its value;
    /// on a gain map the serving AP's (the one received strongest), which achieves `values`
    /// unless another AP, of a weaker budget, has the better channel there (docs/model.md §3).
    pub fn cell_config(&self, index: usize) -> CellConfig {
        match &self.cells {
            CellSolutions::Gain {
                models,
                serving,
                antenna_height_m,
                ..
            } => {
                let (i, j) = self.grid.cell_of(index);
                let [x, y] = self.grid.centre(i, j);
                let ap = serving.get(index).map_or(0, |&k| usize::from(k));
                let model = &models[ap];
                CellConfig {
                    ap,
                    phases: per_surface(
                        gain::waypoint_phases(model, [x, y, *antenna_height_m], self.key.phases),
                        model.surface_lengths(),
                    ),
                    power_w: None,
                    decoding_order: None,
                }
            }
            CellSolutions::Rate(rate) => rate.config(index),
        }
    }

    /// A rate map's cells at other phases than its own ([`RateEvaluator`]); `None` for a gain
    /// map. `scenario` is the map's.
    pub fn rate_evaluator(&self, scenario: &Scenario) -> Option<RateEvaluator<'_>> {
        match &self.cells {
            CellSolutions::Rate(cells) => {
                Some(RateEvaluator::new(scenario, &self.key, &self.grid, cells))
            }
            CellSolutions::Gain { .. } => None,
        }
    }

    /// Bytes the map holds, for cache weighing: its values and occupancy, and what answers
    /// waypoints (the channel models of a gain map, the per-cell solutions of a rate map).
    pub fn size_bytes(&self) -> usize {
        let base = std::mem::size_of::<RadioMap>()
            + self.values.capacity() * std::mem::size_of::<f64>()
            + self.occupied.capacity();
        match &self.cells {
            CellSolutions::Gain {
                models,
                serving,
                serving_gain_db,
                ..
            } => {
                base + serving.capacity()
                    + serving_gain_db.capacity() * std::mem::size_of::<f64>()
                    + models.iter().map(|m| m.heap_bytes()).sum::<usize>()
            }
            CellSolutions::Rate(r) => base + r.size_bytes(),
        }
    }
}

/// Per cell of `grid`: true when something on the floor overlaps the cell's square, not only
/// its centre, the square widened by the robot's radius (docs/model.md §1), so no move between
/// free cells crosses an obstacle or comes closer to one than the radius.
pub fn occupancy(scenario: &Scenario, grid: &Grid) -> Vec<bool> {
    // The robot's radius inflates each cell's square: an obstacle within r of the square in
    // any direction (at most r·√2 at its corners) occupies the cell, so every move between
    // free cells keeps at least r from every obstacle.
    overlapped(
        scenario,
        grid,
        grid.resolution_m / 2.0 + scenario.mru.radius_m,
    )
}

/// Per cell of `grid`: true when something on the floor overlaps the open square of half-side
/// `h` around the cell's centre.
pub(crate) fn overlapped(scenario: &Scenario, grid: &Grid, h: f64) -> Vec<bool> {
    let obstructions = scenario.obstructions();
    let mut occupied = vec![false; grid.cells()];
    obstructions.mark_boxes_and_walls(grid, h, &mut occupied);
    if let Some(raster) = &obstructions.raster {
        let ys: Vec<f64> = (0..grid.ny).map(|j| grid.centre(0, j)[1]).collect();
        let rows = raster.rows_meeting(&ys, h);
        occupied
            .par_chunks_mut(grid.ny)
            .enumerate()
            .for_each_init(Vec::new, |counts, (i, row)| {
                raster.mark_overlapping(grid.centre(i, 0)[0], h, &rows, counts, row);
            });
    }
    occupied
}

/// Builds the map a key defines, named `id`. Cells are spread over rayon's pool by rows of the
/// grid; progress advances and cancellation is checked once per row.
pub fn build(
    scenario: &Scenario,
    key: &MapKey,
    id: String,
    progress: &Progress,
) -> Result<RadioMap, Cancelled> {
    build_resuming(scenario, key, id, progress, &Checkpoint::default())
}

/// [`build`], for a rate map resuming from the rows `checkpoint` holds and recording there the
/// rows it solves (when the checkpoint records). Gain maps ignore it: the slowest, a 1201 × 801
/// floor plan at 5 cm, builds in about 3.5 s, less than a checkpoint's interval.
pub fn build_resuming(
    scenario: &Scenario,
    key: &MapKey,
    id: String,
    progress: &Progress,
    checkpoint: &Checkpoint,
) -> Result<RadioMap, Cancelled> {
    let started = std::time::Instant::now();
    let grid = scenario.grid();
    let occupied = occupancy(scenario, &grid);
    let closed_passages = passages::closed_passages(scenario, &grid, &occupied);
    let links = LinkBudget::for_scenario(scenario);
    progress.start(grid.cells());
    let (values, cells) = match key.kind {
        MapKind::Gain => {
            let height = scenario.mru.antenna_height_m;
            let models: Vec<ChannelModel> = (0..scenario.access_points().len())
                .map(|ap| ChannelModel::for_ap(scenario, ap))
                .collect();
            let offsets: Vec<f64> = links.iter().map(|l| l.offset_dbm).collect();
            let gains = gain::gain_values(
                &models, &offsets, &grid, &occupied, height, key.phases, progress,
            )?;
            let cells = CellSolutions::Gain {
                models: models.into_iter().map(Arc::new).collect(),
                serving: gains.serving,
                serving_gain_db: gains.serving_gain_db,
                antenna_height_m: height,
            };
            (gains.values, cells)
        }
        MapKind::Rate => {
            // Rate maps take one AP (MapKey::new rejects several).
            let model = ChannelModel::new(scenario);
            let (values, rate) = rate_cells::build_rate_cells(
                scenario, &model, &grid, &occupied, key, progress, checkpoint,
            )?;
            (values, CellSolutions::Rate(rate))
        }
    };
    Ok(RadioMap {
        key: key.clone(),
        id,
        grid,
        values,
        occupied,
        closed_passages,
        cells,
        links,
        build_seconds: started.elapsed().as_secs_f64(),
        built_at_unix_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
    })
}
