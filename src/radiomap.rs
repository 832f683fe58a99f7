//! Radio maps (SPEC §2): per free grid cell the best value the MRU can get there, and the
//! configuration that achieves it.
//!
//! * The **channel power gain map** C (paper eq. 15) holds max_θ λ(θ) in dB for the phase mode
//!   `continuous` (closed form, eq. 14), `bits: b` (eq. 14 quantised to L = 2^b levels, eq. 28) or
//!   `none` (direct link only).
//! * The **communication rate map** U (paper eqs. 21 and 27) holds the best expected MRU rate in
//!   bit/s/Hz while every SRU meets its rate; it is computed by [`crate::solver`].
//!
//! A map is identified by its [`MapKey`] (scenario id, kind, phases, access, solver), whose hash is
//! the map id. Occupied cells hold NaN (JSON null, the paper's −∞).

use crate::channel::{C64, ChannelModel, expected_gain};
use crate::scenario::{Grid, Scenario, hash_hex};
use crate::solver::{self, RateCells};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// Largest phase-shifter resolution accepted for `bits` (2^16 levels is continuous in practice).
pub const MAX_PHASE_BITS: u8 = 16;

/// How the IRS phases are chosen (SPEC §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PhaseMode {
    Continuous,
    /// b-bit phase shifters: L = 2^b levels {0, 2π/L, …}.
    Bits(u8),
    /// No IRS term at all.
    None,
}

impl FromStr for PhaseMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "continuous" => Ok(PhaseMode::Continuous),
            "none" => Ok(PhaseMode::None),
            other => match other.parse::<u8>() {
                Ok(b) if (1..=MAX_PHASE_BITS).contains(&b) => Ok(PhaseMode::Bits(b)),
                _ => Err(format!(
                    "expected \"continuous\", \"none\" or a number of bits from 1 to {MAX_PHASE_BITS}, got {other:?}"
                )),
            },
        }
    }
}

impl fmt::Display for PhaseMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PhaseMode::Continuous => f.write_str("continuous"),
            PhaseMode::None => f.write_str("none"),
            PhaseMode::Bits(b) => write!(f, "{b}"),
        }
    }
}

impl Serialize for PhaseMode {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            PhaseMode::Bits(b) => s.serialize_u8(*b),
            other => s.serialize_str(&other.to_string()),
        }
    }
}

impl<'de> Deserialize<'de> for PhaseMode {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        match serde_json::Value::deserialize(d)? {
            serde_json::Value::String(s) => s.parse().map_err(serde::de::Error::custom),
            serde_json::Value::Number(n) => n.to_string().parse().map_err(serde::de::Error::custom),
            other => Err(serde::de::Error::custom(format!(
                "expected \"continuous\", \"none\" or a number of bits, got {other}"
            ))),
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum MapKind {
    /// Channel power gain map (dB).
    Gain,
    /// Communication rate map of the MRU (bit/s/Hz).
    Rate,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Access {
    Noma,
    Oma,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, clap::ValueEnum)]
pub enum SolverKind {
    #[serde(rename = "fast")]
    Fast,
    #[serde(rename = "sdr-sca")]
    #[value(name = "sdr-sca")]
    SdrSca,
}

/// Everything that defines a map; its hash is the map id.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapKey {
    pub scenario_id: String,
    pub kind: MapKind,
    pub phases: PhaseMode,
    /// Rate maps only (default `noma`).
    pub access: Option<Access>,
    /// Rate maps only (default `fast`).
    pub solver: Option<SolverKind>,
}

/// A map request that does not make sense; `field` names the offending parameter.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct KeyError {
    pub field: &'static str,
    pub reason: String,
}

impl MapKey {
    /// Normalises a request: gain maps take no `access`/`solver`, rate maps default them to
    /// `noma`/`fast`, and the scenario must be able to support the kind.
    pub fn new(
        scenario_id: &str,
        scenario: &Scenario,
        kind: MapKind,
        phases: Option<PhaseMode>,
        access: Option<Access>,
        solver: Option<SolverKind>,
    ) -> Result<MapKey, KeyError> {
        let err = |field, reason: &str| {
            Err(KeyError {
                field,
                reason: reason.to_string(),
            })
        };
        let phases = phases.unwrap_or(PhaseMode::Continuous);
        if scenario.irs.is_none() && phases != PhaseMode::None {
            return err("phases", "the scenario has no IRS: only \"none\" applies");
        }
        let (access, solver) = match kind {
            MapKind::Gain => {
                if access.is_some() {
                    return err("access", "applies only to rate maps");
                }
                if solver.is_some() {
                    return err("solver", "applies only to rate maps");
                }
                (None, None)
            }
            MapKind::Rate => {
                if scenario.srus.is_empty() {
                    return err(
                        "kind",
                        "a rate map needs at least one static robot (srus is empty)",
                    );
                }
                let solver = solver.unwrap_or(SolverKind::Fast);
                if solver == SolverKind::SdrSca && !solver::SDR_SCA_AVAILABLE {
                    return err(
                        "solver",
                        "\"sdr-sca\" needs the `sdp` cargo feature (Clarabel with BLAS/LAPACK); this build has it off",
                    );
                }
                (Some(access.unwrap_or(Access::Noma)), Some(solver))
            }
        };
        Ok(MapKey {
            scenario_id: scenario_id.to_string(),
            kind,
            phases,
            access,
            solver,
        })
    }

    /// The map id: hash of the key's canonical JSON.
    pub fn id(&self) -> String {
        hash_hex(
            serde_json::to_string(self)
                .expect("keys serialise")
                .as_bytes(),
        )
    }

    pub fn unit(&self) -> &'static str {
        match self.kind {
            MapKind::Gain => "dB",
            MapKind::Rate => "bit/s/Hz",
        }
    }
}

/// Shared progress and cancellation of one map build.
#[derive(Debug, Default)]
pub struct Progress {
    done: AtomicUsize,
    total: AtomicUsize,
    cancelled: AtomicBool,
}

impl Progress {
    pub fn cells_done(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }
    pub fn cells_total(&self) -> usize {
        self.total.load(Ordering::Relaxed)
    }
    pub fn cancel(&self) {
        self.cancelled.store(true, Ordering::Relaxed);
    }
    pub fn is_cancelled(&self) -> bool {
        self.cancelled.load(Ordering::Relaxed)
    }
    pub(crate) fn start(&self, total: usize) {
        self.total.store(total, Ordering::Relaxed);
        self.done.store(0, Ordering::Relaxed);
    }
    pub(crate) fn advance(&self, cells: usize) {
        self.done.fetch_add(cells, Ordering::Relaxed);
    }
}

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum BuildError {
    #[error("the map build was cancelled")]
    Cancelled,
    #[error("{0}")]
    Solver(String),
}

/// What a map keeps per cell to answer "how do I configure the IRS (and the AP) here?".
#[derive(Debug, Clone)]
pub enum CellSolutions {
    /// Gain maps: θ* is the closed form of eq. 14 (quantised for `bits`), recomputed per waypoint
    /// in O(N) from the channel model rather than stored as N floats per cell (a 1001² map at
    /// N = 60 would otherwise hold 480 MB of phases).
    Gain {
        model: Arc<ChannelModel>,
        antenna_height_m: f64,
    },
    /// Rate maps: the solver's argmax per cell (phases, power split, order, certificate).
    Rate(RateCells),
}

/// The configuration to apply at one waypoint.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CellConfig {
    /// θ_n in [0, 2π), N values (empty without IRS).
    pub irs_phases_rad: Vec<f64>,
    /// Rate maps: transmit power per user (W), MRU first then the SRUs in scenario order.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub power_w: Option<Vec<f64>>,
    /// NOMA rate maps: users in SIC decoding order (decoded first = weakest first).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decoding_order: Option<Vec<String>>,
}

/// A computed radio map.
#[derive(Debug, Clone)]
pub struct RadioMap {
    pub key: MapKey,
    pub grid: Grid,
    /// Per cell (flat index i·ny + j): dB for gain maps, bit/s/Hz for rate maps, NaN if occupied
    /// (and, on rate maps, where no configuration meets every SRU's rate).
    pub values: Vec<f64>,
    /// Per cell: true if an obstacle occupies it.
    pub occupied: Vec<bool>,
    pub cells: CellSolutions,
    /// Wall-clock build time (s).
    pub build_seconds: f64,
}

impl RadioMap {
    /// The configuration achieving `values[index]`.
    pub fn cell_config(&self, index: usize) -> CellConfig {
        match &self.cells {
            CellSolutions::Gain {
                model,
                antenna_height_m,
            } => {
                let (i, j) = self.grid.cell_of(index);
                let [x, y] = self.grid.centre(i, j);
                let n = if self.key.phases == PhaseMode::None {
                    0
                } else {
                    model.subsurfaces()
                };
                let mut phases = vec![0.0; n];
                if n > 0 {
                    phases_for_mode(
                        model,
                        [x, y, *antenna_height_m],
                        self.key.phases,
                        &mut phases,
                    );
                }
                CellConfig {
                    irs_phases_rad: phases,
                    power_w: None,
                    decoding_order: None,
                }
            }
            CellSolutions::Rate(rate) => rate.config(index),
        }
    }

    /// Approximate heap size, for cache weighing.
    pub fn size_bytes(&self) -> usize {
        let base = self.values.len() * 9 + 256;
        match &self.cells {
            CellSolutions::Gain { .. } => base,
            CellSolutions::Rate(r) => base + r.size_bytes(),
        }
    }

    /// Summary statistics over the free cells with a finite value.
    pub fn stats(&self) -> MapStats {
        let mut finite: Vec<f64> = self
            .values
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        finite.sort_by(f64::total_cmp);
        let free = self.occupied.iter().filter(|o| !**o).count();
        let pick = |q: f64| {
            finite
                .get(((finite.len() - 1) as f64 * q).round() as usize)
                .copied()
        };
        MapStats {
            cells: self.values.len(),
            free_cells: free,
            occupied_cells: self.values.len() - free,
            valued_cells: finite.len(),
            min: finite.first().copied(),
            max: finite.last().copied(),
            mean: (!finite.is_empty()).then(|| finite.iter().sum::<f64>() / finite.len() as f64),
            median: if finite.is_empty() { None } else { pick(0.5) },
        }
    }
}

/// How close the rate map is to the SDR bound over its cells (bit/s/Hz).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CertificateSummary {
    /// Cells with both an achieved rate and a finite bound.
    pub cells: usize,
    pub median_gap: Option<f64>,
    pub mean_gap: Option<f64>,
    pub max_gap: Option<f64>,
}

/// The JSON body of a map (CLI `map` and `GET /v1/maps/{id}`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapBody {
    pub map_id: String,
    pub key: MapKey,
    pub unit: &'static str,
    pub grid: Grid,
    pub stats: MapStats,
    /// values[i][j] is the cell at (x_min + i·Δ, y_min + j·Δ); null where occupied (or, on rate
    /// maps, where no configuration serves every SRU).
    pub values: Vec<Vec<Option<f64>>>,
    /// Rate maps: the certificate summary.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub certificate: Option<CertificateSummary>,
    /// Rate maps: the SDR upper bound per cell, laid out like `values`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub upper_bound: Option<Vec<Vec<Option<f64>>>>,
}

impl RadioMap {
    fn as_rows(&self, data: &[f64]) -> Vec<Vec<Option<f64>>> {
        data.chunks(self.grid.ny)
            .map(|row| row.iter().map(|v| v.is_finite().then_some(*v)).collect())
            .collect()
    }

    /// The map's JSON body.
    pub fn body(&self) -> MapBody {
        let (certificate, upper_bound) = match &self.cells {
            CellSolutions::Gain { .. } => (None, None),
            CellSolutions::Rate(rate) => {
                let mut gaps = rate.gaps(&self.values);
                gaps.sort_by(f64::total_cmp);
                let summary = CertificateSummary {
                    cells: gaps.len(),
                    median_gap: (!gaps.is_empty()).then(|| gaps[gaps.len() / 2]),
                    mean_gap: (!gaps.is_empty())
                        .then(|| gaps.iter().sum::<f64>() / gaps.len() as f64),
                    max_gap: gaps.last().copied(),
                };
                (Some(summary), Some(self.as_rows(&rate.upper_bound)))
            }
        };
        MapBody {
            map_id: self.key.id(),
            key: self.key.clone(),
            unit: self.key.unit(),
            grid: self.grid,
            stats: self.stats(),
            values: self.as_rows(&self.values),
            certificate,
            upper_bound,
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapStats {
    pub cells: usize,
    pub free_cells: usize,
    pub occupied_cells: usize,
    /// Free cells with a value (on rate maps, those where every SRU can be served).
    pub valued_cells: usize,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub mean: Option<f64>,
    pub median: Option<f64>,
}

/// η(γ) of paper eq. 29: the share of free cells whose value is ≥ γ.
pub fn coverage(map: &RadioMap, threshold: f64) -> f64 {
    let free = map.occupied.iter().filter(|o| !**o).count();
    if free == 0 {
        return 0.0;
    }
    map.values.iter().filter(|v| **v >= threshold).count() as f64 / free as f64
}

/// The phases of a mode at `user`: θ* of eq. 14, quantised for `bits` to the nearest of
/// L = 2^b levels modulo 2π (eq. 28). All phases land in [0, 2π).
pub fn phases_for_mode(model: &ChannelModel, user: [f64; 3], mode: PhaseMode, out: &mut [f64]) {
    model.optimal_phases(user, out);
    if let PhaseMode::Bits(b) = mode {
        out.iter_mut().for_each(|t| *t = quantise_phase(*t, b));
    }
}

/// The level of {0, δ, …, (L−1)δ}, δ = 2π/L, nearest to θ modulo 2π.
pub fn quantise_phase(theta: f64, bits: u8) -> f64 {
    let levels = (1u32 << bits) as f64;
    let step = TAU / levels;
    ((theta / step).round() % levels) * step
}

/// The best expected gain λ (linear) at `user` for a phase mode, using the buffers `w` (N) and
/// `theta` (N): `continuous`: (|h̃| + ‖w̃‖₁)² + τ (paper eq. 15); `bits`: λ (eq. 6) at the
/// quantised eq. 14 phases (eq. 28); `none`: |h̃|² + τ of the direct link alone.
pub fn best_gain(
    model: &ChannelModel,
    user: [f64; 3],
    mode: PhaseMode,
    w: &mut [C64],
    theta: &mut [f64],
) -> f64 {
    let direct = model.evaluate(user, mode != PhaseMode::None, w);
    match mode {
        PhaseMode::None => direct.h.norm_sqr() + direct.tau,
        PhaseMode::Continuous => {
            let l1: f64 = w.iter().map(|x| x.norm()).sum();
            (direct.h.norm() + l1).powi(2) + direct.tau
        }
        PhaseMode::Bits(_) => {
            phases_for_mode(model, user, mode, theta);
            expected_gain(&direct, w, theta)
        }
    }
}

/// Builds the map a key defines. Cells are spread over rayon's pool by rows of the grid; progress
/// advances and cancellation is checked once per row.
pub fn build(
    scenario: &Scenario,
    key: &MapKey,
    progress: &Progress,
) -> Result<RadioMap, BuildError> {
    let started = std::time::Instant::now();
    let grid = scenario.grid();
    let model = Arc::new(ChannelModel::new(scenario));
    let occupied: Vec<bool> = (0..grid.cells())
        .map(|k| {
            let (i, j) = grid.cell_of(k);
            let [x, y] = grid.centre(i, j);
            scenario.is_occupied(x, y)
        })
        .collect();
    progress.start(grid.cells());
    let (values, cells) = match key.kind {
        MapKind::Gain => {
            let values = gain_values(
                &model,
                &grid,
                &occupied,
                scenario.mru.antenna_height_m,
                key.phases,
                progress,
            )?;
            (
                values,
                CellSolutions::Gain {
                    model,
                    antenna_height_m: scenario.mru.antenna_height_m,
                },
            )
        }
        MapKind::Rate => {
            let (values, rate) =
                solver::build_rate_cells(scenario, &model, &grid, &occupied, key, progress)?;
            (values, CellSolutions::Rate(rate))
        }
    };
    Ok(RadioMap {
        key: key.clone(),
        grid,
        values,
        occupied,
        cells,
        build_seconds: started.elapsed().as_secs_f64(),
    })
}

fn gain_values(
    model: &ChannelModel,
    grid: &Grid,
    occupied: &[bool],
    height: f64,
    mode: PhaseMode,
    progress: &Progress,
) -> Result<Vec<f64>, BuildError> {
    let mut values = vec![f64::NAN; grid.cells()];
    values
        .par_chunks_mut(grid.ny)
        .zip(occupied.par_chunks(grid.ny))
        .enumerate()
        .try_for_each_init(
            || {
                (
                    vec![C64::new(0.0, 0.0); model.subsurfaces()],
                    vec![0.0; model.subsurfaces()],
                )
            },
            |(w, theta), (i, (row, occupied_row))| {
                if progress.is_cancelled() {
                    return Err(BuildError::Cancelled);
                }
                for (j, (value, &occ)) in row.iter_mut().zip(occupied_row).enumerate() {
                    if occ {
                        continue;
                    }
                    let [x, y] = grid.centre(i, j);
                    *value = 10.0 * best_gain(model, [x, y, height], mode, w, theta).log10();
                }
                progress.advance(row.len());
                Ok(())
            },
        )?;
    Ok(values)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::channel::expected_gain;
    use rand::{RngExt, SeedableRng};

    fn small() -> Scenario {
        Scenario::from_json(include_str!("../scenarios/small-test.json")).unwrap()
    }

    fn gain_key(s: &Scenario, phases: PhaseMode) -> MapKey {
        MapKey::new("test", s, MapKind::Gain, Some(phases), None, None).unwrap()
    }

    /// The closed form (eq. 15) is at least the best of many random θ, equals λ at the eq. 14
    /// phases, and is the triangle-inequality bound (eq. 13) that no θ exceeds.
    #[test]
    fn closed_form_beats_random_phases_and_meets_the_bound() {
        for grouping in ["coherent", "elements"] {
            let mut v: serde_json::Value =
                serde_json::from_str(include_str!("../scenarios/small-test.json")).unwrap();
            v["irs"]["grouping"] = grouping.into();
            let s = Scenario::from_json(&v.to_string()).unwrap();
            let model = ChannelModel::new(&s);
            let mut rng = rand::rngs::StdRng::seed_from_u64(3);
            let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
            let mut theta = vec![0.0; w.len()];
            for _ in 0..40 {
                let q = [rng.random_range(0.0..6.0), rng.random_range(0.2..4.0), 1.0];
                let d = model.evaluate(q, true, &mut w);
                let best = best_gain(&model, q, PhaseMode::Continuous, &mut w, &mut theta);
                let bound = (d.h.norm() + w.iter().map(|x| x.norm()).sum::<f64>()).powi(2) + d.tau;
                assert!((best - bound).abs() <= 1e-12 * bound);
                // Eq. 14's phases (from distances) attain the closed form.
                model.optimal_phases(q, &mut theta);
                assert!(
                    (expected_gain(&d, &w, &theta) / best - 1.0).abs() < 1e-12,
                    "{grouping} at {q:?}"
                );
                for _ in 0..500 {
                    let random: Vec<f64> =
                        (0..w.len()).map(|_| rng.random::<f64>() * TAU).collect();
                    assert!(expected_gain(&d, &w, &random) <= best * (1.0 + 1e-12));
                }
            }
        }
    }

    #[test]
    fn quantised_phases_never_beat_continuous_and_none_is_the_direct_link() {
        let s = small();
        let progress = Progress::default();
        let cont = build(&s, &gain_key(&s, PhaseMode::Continuous), &progress).unwrap();
        let none = build(&s, &gain_key(&s, PhaseMode::None), &progress).unwrap();
        let model = ChannelModel::new(&s);
        for b in 1..=3 {
            let q = build(&s, &gain_key(&s, PhaseMode::Bits(b)), &progress).unwrap();
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
    fn quantisation_wraps_modulo_two_pi() {
        assert_eq!(quantise_phase(TAU - 0.01, 1), 0.0);
        assert!((quantise_phase(3.0, 1) - std::f64::consts::PI).abs() < 1e-15);
        assert!((quantise_phase(1.0, 2) - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    }

    #[test]
    fn keys_reject_what_does_not_apply() {
        let s = small();
        let e = MapKey::new("x", &s, MapKind::Gain, None, Some(Access::Oma), None).unwrap_err();
        assert_eq!(e.field, "access");
        let rate = MapKey::new("x", &s, MapKind::Rate, None, None, None).unwrap();
        assert_eq!(
            (rate.access, rate.solver),
            (Some(Access::Noma), Some(SolverKind::Fast))
        );
        assert_ne!(rate.id(), gain_key(&s, PhaseMode::Continuous).id());
        assert!("0".parse::<PhaseMode>().is_err());
        assert_eq!("3".parse::<PhaseMode>(), Ok(PhaseMode::Bits(3)));
    }

    #[test]
    fn sdr_sca_without_the_sdp_feature_is_a_clear_error() {
        let s = small();
        let key = MapKey::new("x", &s, MapKind::Rate, None, None, Some(SolverKind::SdrSca));
        if solver::SDR_SCA_AVAILABLE {
            assert_eq!(key.unwrap().solver, Some(SolverKind::SdrSca));
        } else {
            let e = key.unwrap_err();
            assert_eq!(e.field, "solver");
            assert!(e.reason.contains("sdp"), "{e}");
        }
    }

    #[test]
    fn cancellation_stops_a_build() {
        let s = small();
        let progress = Progress::default();
        progress.cancel();
        let r = build(&s, &gain_key(&s, PhaseMode::Continuous), &progress);
        assert_eq!(r.unwrap_err(), BuildError::Cancelled);
    }
}
