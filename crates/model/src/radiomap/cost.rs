//! What a build will cost before it starts: an estimate of its CPU time from the sizes that
//! drive it (cells × scattering points × APs for gain maps; cells × N × users for rate maps,
//! × decoding orders for `sdr-sca`), so a service can refuse work beyond its budget before
//! spending any of it.
//!
//! The constants are per-unit times measured with `cargo bench` on the project's 2-core
//! machine (one core, release build), rounded up: estimates err on the side of refusing.
//! Every product is taken in `f64`, which cannot wrap: a scenario that passed validation has
//! at most 1001² cells, 200 000 elements and 8 APs, so the largest product (≈ 10¹⁸) is still
//! represented to a few parts in 10¹⁶.

use super::{MapKey, MapKind};
use crate::geometry::SightLines;
use crate::phases::PhaseMode;
use crate::scenario::{Grouping, Scenario};
use crate::solver::SolverKind;

/// Seconds per (cell · AP · scattering point) of a gain map evaluated cell by cell: an
/// `elements` surface of 1 200 points over the open 401² floor takes 3.95 s, 20 ns a unit.
/// (Built a row at a time a cell costs per link, not per point: [`ROW_LINK_S`].)
const GAIN_S_PER_POINT: f64 = 20e-9;
/// A `bits` gain map also quantises the phases and sums the channel at them: about twice the
/// work of the closed form.
const BITS_FACTOR: f64 = 2.0;
/// Seconds per (cell · user weight · N) of a rate map with the `fast` solver and its
/// certificate, one core, where K SRUs weigh [`fast_user_weight`] (2 for one SRU): a cold
/// cell of the paper's NOMA map with one SRU costs 0.5–0.6 ms at N = 60 and 1.4–2.1 ms at
/// N = 256 (README "Performance"), 4.2–4.6 µs a unit; the warm-started cells of
/// a map cost less, so 5 µs over-estimates a map, never under.
const RATE_S_PER_POINT_WEIGHT: f64 = 5e-6;
/// Seconds per (cell · decoding order · (N + 1)³) of `sdr-sca`, which solves SDPs of size N + 1
/// (interior-point work grows as its cube): 0.22–0.33 s a cell at N = 10 with 2 orders
/// (`scripts/solver-ratio.sh`), 83–124 µs a unit.
const SDR_SCA_S_PER_CUBE_ORDER: f64 = 150e-6;

/// Seconds per blockage-tested link of a gain map built a row at a time (continuous phases,
/// `coherent` surfaces: `ChannelModel::closed_form_row`), besides its obstacles: the path gain
/// and the closed form's few terms, vectorised over the row. The paper's floor at 401² (two
/// links a cell, five boxes): 15 ms, 47 ns a link.
const ROW_LINK_S: f64 = 60e-9;
/// Seconds per (link · box) and (link · wall) of a row (`Obstructions::blocks_row`): every
/// wall is tested against every link of a row, a box against the links of its shadow on the
/// row and the rest only by bounds. The reliability suite's 1000 boxes at 401²: 0.05 s of CPU
/// in all, 0.15 ns a (link · box) after the links' own cost; 1000 walls: 0.97 s, 3.9 ns.
const ROW_BOX_S: f64 = 0.15e-9;
const ROW_WALL_S: f64 = 5e-9;
/// Seconds per floor-plan column a blockage test looks at (`Raster::columns_walked`: the
/// columns it leaps over through open floor are not counted, and each one looked at costs a
/// dependent memory access): the reliability suite's `cpu-budget` floors over 2048² plans,
/// empty and cluttered, were estimated at 1.0× and 0.7× the CPU they measure. A map's rows now
/// settle most links by the source's horizon (`geometry::Horizon`) without a walk, and the same
/// floors are estimated at 1.8–2.4× and 1.6× (three runs): an over-estimate, within the suite's
/// 3×, kept because the walk's cost still bounds what a horizon cannot settle.
const PIXEL_S: f64 = 15e-9;
/// Seconds per link of a map built cell by cell (phases in bits, `elements` surfaces), besides
/// its obstacles, and per box or wall of the link's own direction (`SightLines`): set so that
/// the `cpu-budget` case of the reliability suite (2-bit phases over 1 000 boxes or walls)
/// lands within its bounds, rounded up.
const CELL_LINK_S: f64 = 100e-9;
const CELL_BOX_S: f64 = 2e-9;
const CELL_WALL_S: f64 = 5e-9;
/// Links sampled per source to learn what a blockage test costs on this floor: a lattice of
/// 16 × 16 grid cells. A link is tested only against the obstacles of its direction, and it
/// stops walking a floor plan at its first occupied pixel, so the cost depends on where the
/// obstacles and the clutter are, which only a sample knows (256 walks of at most 4096 columns
/// a source: a few milliseconds at worst).
const SAMPLE_SIDE: usize = 16;

/// What a floor does to the cost of its cells, from a sample of them and of their links.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LinkSample {
    /// Boxes a link's blockage test looks at, on average (those of its direction).
    pub boxes: f64,
    /// Walls a link's blockage test looks at, on average.
    pub walls: f64,
    /// Floor-plan columns a link's blockage test walks, on average.
    pub columns: f64,
    /// The share of cells that are free: an occupied cell is skipped.
    pub free: f64,
}

/// The [`LinkSample`] of a lattice of cells and their links from each AP and IRS centre.
pub fn sample_links(scenario: &Scenario) -> LinkSample {
    let obstructions = scenario.obstructions();
    let grid = scenario.grid();
    let height = scenario.mru.antenna_height_m;
    let pick = |n: usize, k: usize| k * (n - 1) / (SAMPLE_SIDE - 1);
    let users: Vec<(nalgebra::Vector3<f64>, bool)> = (0..SAMPLE_SIDE * SAMPLE_SIDE)
        .map(|k| {
            let [x, y] = grid.centre(
                pick(grid.nx, k / SAMPLE_SIDE),
                pick(grid.ny, k % SAMPLE_SIDE),
            );
            (
                nalgebra::Vector3::new(x, y, height),
                !obstructions.overlaps_square(x, y, grid.resolution_m / 2.0),
            )
        })
        .collect();
    let free_users = users.iter().filter(|(_, free)| *free).count();
    let aps = scenario.access_points().iter().map(|ap| ap.position);
    let surfaces = scenario.surfaces().iter().map(|irs| irs.center);
    let (mut sum, mut links) = (LinkSample::default(), 0);
    for source in aps.chain(surfaces) {
        let sight = SightLines::new(&obstructions, source);
        let source = nalgebra::Vector3::from(source);
        for (user, _) in users.iter().filter(|(_, free)| *free) {
            let (boxes, walls) = sight.listed_towards(&obstructions, user);
            sum.boxes += boxes as f64;
            sum.walls += walls as f64;
            if let Some(raster) = &obstructions.raster {
                sum.columns += raster.columns_walked(&source, user) as f64;
            }
            links += 1;
        }
    }
    let per_link = |total: f64| total / links.max(1) as f64;
    LinkSample {
        boxes: per_link(sum.boxes),
        walls: per_link(sum.walls),
        columns: per_link(sum.columns),
        free: free_users as f64 / users.len() as f64,
    }
}

/// What a surface's point costs for an AP that does not see the surface's centre, against
/// one it sees: its reflected field is not summed, its scattered power still is. An `elements`
/// surface of 1 200 points behind 1 000 walls: 0.06 s against 3.8 s in sight at 401² (with
/// most of the cells behind the walls occupied), 0.02 a free cell; rounded up.
const UNLIT_SHARE: f64 = 0.03;

/// Scattering points a cell sums over all APs (the direct link counts one), a surface's
/// weighed by [`UNLIT_SHARE`] for an AP that does not see it.
fn lit_points(scenario: &Scenario) -> f64 {
    let obstructions = scenario.obstructions();
    let surfaces = scenario.surfaces();
    scenario
        .access_points()
        .iter()
        .map(|ap| {
            let points: f64 = surfaces
                .iter()
                .map(|irs| {
                    let points = match irs.grouping {
                        Grouping::Coherent => irs.subsurfaces() as f64,
                        Grouping::Elements => irs.elements() as f64,
                    };
                    if obstructions.blocks(ap.position, irs.center) {
                        points * UNLIT_SHARE
                    } else {
                        points
                    }
                })
                .sum();
            1.0 + points
        })
        .sum()
}

/// Blockage-tested links per grid cell of a gain map: from each AP and, for each AP, from each
/// IRS centre (the IRS–user link is tested again for every AP's model).
pub fn links_per_cell(scenario: &Scenario) -> f64 {
    let aps = scenario.access_points().len() as f64;
    aps * (1.0 + scenario.surfaces().len() as f64)
}

/// How gain-map cells are evaluated: a map a row at a time where its mode and surfaces allow
/// (`radiomap::gain`), a placement search cell by cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Evaluation {
    /// A map: a row at a time where it can be.
    Rows,
    /// A search: cell by cell.
    Cells,
}

/// Whether a gain map in `mode` is built a row at a time (`radiomap::gain`).
fn by_rows(scenario: &Scenario, mode: PhaseMode) -> bool {
    mode == PhaseMode::Continuous
        && scenario
            .surfaces()
            .iter()
            .all(|irs| irs.grouping == Grouping::Coherent)
}

/// Scattering points the channel model evaluates per cell and AP: N sub-surface centres for a
/// `coherent` surface, M elements for an `elements` one.
pub fn scattering_points(scenario: &Scenario) -> f64 {
    scenario
        .surfaces()
        .iter()
        .map(|irs| match irs.grouping {
            Grouping::Coherent => irs.subsurfaces() as f64,
            Grouping::Elements => irs.elements() as f64,
        })
        .sum()
}

/// Estimated seconds of one core to evaluate `cell_evaluations` gain-map cells of `scenario`
/// (each against every AP) in phase mode `mode`, cell by cell (as a placement search does) or,
/// where the map allows it, a row at a time.
pub fn gain_seconds(
    scenario: &Scenario,
    cell_evaluations: f64,
    mode: PhaseMode,
    evaluation: Evaluation,
) -> f64 {
    let sample = sample_links(scenario);
    let links = links_per_cell(scenario);
    let raster = sample.columns * PIXEL_S;
    let per_cell = if evaluation == Evaluation::Rows && by_rows(scenario, mode) {
        let (boxes, walls) = (scenario.obstacles.len() as f64, scenario.walls.len() as f64);
        sample.free * links * (ROW_LINK_S + boxes * ROW_BOX_S + walls * ROW_WALL_S + raster)
    } else {
        // Phases in bits evaluate each cell twice: at the optimum, then quantised.
        let factor = if matches!(mode, PhaseMode::Bits(_)) {
            BITS_FACTOR
        } else {
            1.0
        };
        let channel = lit_points(scenario) * GAIN_S_PER_POINT;
        let blockage =
            CELL_LINK_S + sample.boxes * CELL_BOX_S + sample.walls * CELL_WALL_S + raster;
        sample.free * factor * (channel + links * blockage)
    };
    cell_evaluations * per_cell
}

/// Estimated seconds of one core to build the map `key` of `scenario`.
pub fn build_seconds(scenario: &Scenario, key: &MapKey) -> f64 {
    let cells = scenario.grid().cells() as f64;
    match key.kind {
        MapKind::Gain => gain_seconds(scenario, cells, key.phases, Evaluation::Rows),
        MapKind::Rate => {
            let n = scenario
                .surfaces()
                .iter()
                .map(|irs| irs.subsurfaces())
                .sum::<usize>()
                .max(1) as f64;
            let srus = scenario.srus.len();
            if key.solver == Some(SolverKind::SdrSca) {
                // Every decoding order's SDPs are solved.
                let orders = (1..=srus + 1).map(|k| k as f64).product::<f64>();
                cells * orders * (n + 1.0).powi(3) * SDR_SCA_S_PER_CUBE_ORDER
            } else {
                cells * fast_user_weight(srus) * n * RATE_S_PER_POINT_WEIGHT
            }
        }
    }
}

/// How a rate cell's work (the `fast` search and the certificate) grows with K SRUs. One SRU
/// weighs 2: one pair family and the polygon certificate. With K ≥ 2 the certificate's joint
/// dual runs once per decoding order that its box bound cannot prune, and that dominates:
/// 1.5 K². Fitted to the paper's multi-user floor with 1–4 SRUs (41², N = 60, NOMA; 2026-12-07,
/// docs/performance.md "Several SRUs certified"): 0.46, 1.07, 2.60 and 5.33 s of CPU, ratios
/// 1 : 2.3 : 5.7 : 11.7 against this weight's 1 : 3 : 6.8 : 12, so a map is over-estimated,
/// not under. Since K ≥ 2 cells are warm-started (performance.md "Several SRUs, warm where
/// proved"), 0.46–0.50, 0.68, 2.21 and 4.02 s: 1 : 1.4 : 4.6 : 8.4, over-estimated further.
/// The weight stays: a map over-estimated waits in the queue longer than it needs, while one
/// under-estimated would overload the workers.
fn fast_user_weight(srus: usize) -> f64 {
    let k = srus as f64;
    if srus <= 1 { 2.0 } else { 1.5 * k * k }
}

/// Estimated bytes of the built map, as the cache weighs it ([`super::RadioMap::size_bytes`]):
/// per cell a value and an occupancy flag, and then per cell the serving AP (gain maps) or the
/// phases, powers, bound and decoding order (rate maps); a gain map also keeps one channel
/// model per AP (32 bytes per scattering point and its obstacle index).
pub fn map_bytes(scenario: &Scenario, key: &MapKey) -> f64 {
    let cells = scenario.grid().cells() as f64;
    let base = cells * 9.0;
    match key.kind {
        MapKind::Gain => {
            let aps = scenario.access_points().len() as f64;
            let (boxes, walls) = (scenario.obstacles.len(), scenario.walls.len());
            // Each AP's model: its scattering points, the obstacles, and a direction index of
            // them (and a floor plan's horizon) from the AP and from every IRS centre.
            let sources = (1 + scenario.surfaces().len()) as f64;
            let plan = scenario.floor_plan.is_some();
            let index = SightLines::estimated_heap_bytes(boxes, walls, plan) as f64;
            let model = 32.0 * scattering_points(scenario) + 64.0 * (boxes + walls) as f64;
            base + cells + aps * (model + sources * index)
        }
        MapKind::Rate => {
            let n = if key.phases == PhaseMode::None {
                0.0
            } else {
                scenario
                    .surfaces()
                    .iter()
                    .map(|s| s.subsurfaces() as f64)
                    .sum()
            };
            let users = 1.0 + scenario.srus.len() as f64;
            // f64 bound and powers, u16 phase codes, one order byte.
            base + cells * (8.0 * (users + 1.0) + 2.0 * n + 1.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_grow_with_what_drives_the_work() {
        let paper = Scenario::builtin("paper-single-user").unwrap();
        let key = MapKey::new("x", &paper, MapKind::Gain, None, None, None).unwrap();
        let seconds = build_seconds(&paper, &key);
        // The paper's 41² map builds in about 60 µs (criterion, docs/performance.md).
        assert!((3e-5..1e-3).contains(&seconds), "{seconds}");
        let elements = Scenario::builtin_with("paper-single-user", |v| {
            v["irs"]["grouping"] = "elements".into()
        })
        .unwrap()
        .unwrap();
        let more = build_seconds(&elements, &key);
        assert!(more > 5.0 * seconds, "{more} vs {seconds}");
        // Walls are tested by every link of a row: 1000 of them cost about a second at 401².
        let walled = Scenario::builtin_with("paper-single-user", |v| {
            v["grid"]["resolution_m"] = 0.05.into();
            v["walls"] = (0..1000)
                .map(|k| {
                    let x = -9.0 + 18.0 * f64::from(k % 40) / 40.0;
                    let y = -8.0 + 16.0 * f64::from(k / 40) / 25.0;
                    serde_json::json!({"from": [x, y], "to": [x + 0.3, y], "thickness_m": 0.1, "height_m": 2.5})
                })
                .collect();
            v["obstacles"] = serde_json::json!([]);
        })
        .unwrap()
        .unwrap();
        let walled_key = MapKey::new("x", &walled, MapKind::Gain, None, None, None).unwrap();
        let walled_seconds = build_seconds(&walled, &walled_key);
        assert!((0.5..5.0).contains(&walled_seconds), "{walled_seconds}");
        // Cell by cell (a search), a link meets only the walls of its direction.
        let cells = walled.grid().cells() as f64;
        let searched = gain_seconds(&walled, cells, PhaseMode::Continuous, Evaluation::Cells);
        let sample = sample_links(&walled);
        assert!(sample.walls < 500.0 && sample.walls > 1.0, "{sample:?}");
        assert!(searched < walled_seconds, "{searched} vs {walled_seconds}");
        let multi = Scenario::builtin("paper-multi-user").unwrap();
        let rate = MapKey::new("x", &multi, MapKind::Rate, None, None, None).unwrap();
        // The paper's NOMA map: 0.5 s measured on one core; the estimate must not be below it.
        let rate_seconds = build_seconds(&multi, &rate);
        assert!((0.5..5.0).contains(&rate_seconds), "{rate_seconds}");
    }

    /// The size estimate is what the cache will weigh, within 10 %, for both kinds.
    #[test]
    fn map_bytes_are_estimated_before_the_build() {
        let multi = Scenario::builtin("paper-multi-user").unwrap();
        for kind in [MapKind::Gain, MapKind::Rate] {
            let key = MapKey::new("x", &multi, kind, None, None, None).unwrap();
            let map =
                super::super::build(&multi, &key, "test".into(), &Default::default()).unwrap();
            let (estimate, actual) = (map_bytes(&multi, &key), map.size_bytes() as f64);
            assert!(
                (estimate / actual - 1.0).abs() < 0.1,
                "{kind}: estimated {estimate}, weighed {actual}"
            );
        }
    }
}
