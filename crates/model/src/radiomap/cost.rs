//! What a build will cost before it starts: an estimate of its CPU time from the sizes that
//! drive it (cells × scattering points × APs for gain maps; cells × N² × decoding orders for
//! rate maps), so a service can refuse work beyond its budget before spending any of it.
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

/// Seconds per (cell · AP · scattering point) of a gain map with continuous phases: the paper's
/// 1001² map (N = 60 points, one AP) takes 0.45 s, 7.5 ns a unit; 10 ns leaves room for a
/// floor plan's blockage tests.
const GAIN_S_PER_POINT: f64 = 10e-9;
/// A `bits` gain map also quantises the phases and sums the channel at them: about twice the
/// work of the closed form.
const BITS_FACTOR: f64 = 2.0;
/// Seconds per (cell · decoding order · N) of a rate map with the `fast` solver and its
/// certificate, one core: a cold cell of the paper's NOMA map (2 orders) costs 0.5–0.6 ms at
/// N = 60 and 1.4–2.1 ms at N = 256 (README "Performance"), 4.2–4.6 µs a unit; the warm-started
/// cells of a map cost less, so 5 µs over-estimates a map, never under.
const RATE_S_PER_POINT_ORDER: f64 = 5e-6;
/// Seconds per (cell · decoding order · (N + 1)³) of `sdr-sca`, which solves SDPs of size N + 1
/// (interior-point work grows as its cube): 0.22–0.33 s a cell at N = 10 with 2 orders
/// (`scripts/solver-ratio.sh`), 83–124 µs a unit.
const SDR_SCA_S_PER_CUBE_ORDER: f64 = 150e-6;

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
/// (each against every AP) in phase mode `mode`.
pub fn gain_seconds(scenario: &Scenario, cell_evaluations: f64, mode: PhaseMode) -> f64 {
    // The direct link costs about one scattering point.
    let points = 1.0 + scattering_points(scenario);
    let factor = if matches!(mode, PhaseMode::Bits(_)) {
        BITS_FACTOR
    } else {
        1.0
    };
    cell_evaluations * scenario.access_points().len() as f64 * points * GAIN_S_PER_POINT * factor
}

/// Estimated seconds of one core to build the map `key` of `scenario`.
pub fn build_seconds(scenario: &Scenario, key: &MapKey) -> f64 {
    let cells = scenario.grid().cells() as f64;
    match key.kind {
        MapKind::Gain => gain_seconds(scenario, cells, key.phases),
        MapKind::Rate => {
            let n = scenario
                .surfaces()
                .iter()
                .map(|irs| irs.subsurfaces())
                .sum::<usize>()
                .max(1) as f64;
            let orders = (1..=scenario.srus.len() + 1)
                .map(|k| k as f64)
                .product::<f64>();
            let per_order = if key.solver == Some(SolverKind::SdrSca) {
                (n + 1.0).powi(3) * SDR_SCA_S_PER_CUBE_ORDER
            } else {
                n * RATE_S_PER_POINT_ORDER
            };
            cells * orders * per_order
        }
    }
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
            // them from the AP and from every IRS centre.
            let sources = (1 + scenario.surfaces().len()) as f64;
            let index = SightLines::estimated_heap_bytes(boxes, walls) as f64;
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
        // The paper's 41² map builds in ~1.5 ms; the estimate is of that order, not below it.
        assert!((1e-3..0.05).contains(&seconds), "{seconds}");
        let elements = Scenario::builtin_with("paper-single-user", |v| {
            v["irs"]["grouping"] = "elements".into()
        })
        .unwrap()
        .unwrap();
        let more = build_seconds(&elements, &key);
        assert!(more > 5.0 * seconds, "{more} vs {seconds}");
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
