//! What a built map says about itself: summary statistics, coverage η(γ) (eq. 44) and the
//! certificate summary of rate maps.

use super::{CellSolutions, RadioMap};
use serde::Serialize;

/// Summary statistics of a map's values (dB or bit/s/Hz) over its free cells with a value.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MapStats {
    /// Cells of the grid, occupied ones included.
    pub cells: usize,
    /// Cells no obstruction overlaps (docs/model.md §1).
    pub free_cells: usize,
    /// Cells an obstruction overlaps (never a waypoint).
    pub occupied_cells: usize,
    /// Passages a robot could drive through that no chain of free cells crosses at this grid's
    /// resolution (listed in the map's body; docs/model.md §1).
    pub closed_passages: usize,
    /// Free cells with a value (on rate maps, those where every SRU can be served).
    pub valued_cells: usize,
    /// Smallest value; `None` when no cell has one.
    pub min: Option<f64>,
    /// Largest value; `None` when no cell has one.
    pub max: Option<f64>,
    /// Mean value; `None` when no cell has one.
    pub mean: Option<f64>,
    /// Median value (of an even count, the upper middle one); `None` when no cell has one.
    pub median: Option<f64>,
}

/// How close the rate map is to the SDR bound over its cells (bit/s/Hz).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CertificateSummary {
    /// Cells with both an achieved rate and a finite bound.
    pub cells: usize,
    /// Median of upper_bound − achieved (of an even count, the upper middle one); `None` without
    /// cells.
    pub median_gap: Option<f64>,
    /// Mean of upper_bound − achieved; `None` without cells.
    pub mean_gap: Option<f64>,
    /// Largest upper_bound − achieved: the worst-certified cell; `None` without cells.
    pub max_gap: Option<f64>,
}

impl RadioMap {
    /// Summary statistics over the free cells with a finite value.
    pub fn stats(&self) -> MapStats {
        self.stats_of(&self.values)
    }

    /// [`RadioMap::stats`] of `values`, this map's values in another unit
    /// ([`RadioMap::values_in`]).
    pub fn stats_of(&self, values: &[f64]) -> MapStats {
        let mut finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
        let free = self.free_cells();
        let (min, max, sum) = finite.iter().fold(
            (f64::INFINITY, f64::NEG_INFINITY, 0.0),
            |(lo, hi, sum), &v| (lo.min(v), hi.max(v), sum + v),
        );
        let some = !finite.is_empty();
        MapStats {
            cells: values.len(),
            free_cells: free,
            occupied_cells: values.len() - free,
            closed_passages: self.closed_passages.total,
            valued_cells: finite.len(),
            min: some.then_some(min),
            max: some.then_some(max),
            mean: some.then(|| sum / finite.len() as f64),
            median: upper_median(&mut finite),
        }
    }

    /// Υ's complement: the cells no obstacle occupies.
    pub fn free_cells(&self) -> usize {
        self.occupied.iter().filter(|o| !**o).count()
    }

    /// η(γ) of paper eq. 44: the share of free cells whose value is ≥ γ.
    pub fn coverage(&self, threshold: f64) -> f64 {
        coverage(&self.values, &self.occupied, threshold)
    }

    /// The certificate summary of a rate map (None for gain maps): how close its values are to
    /// the SDR bound over its cells.
    pub fn certificate_summary(&self) -> Option<CertificateSummary> {
        let CellSolutions::Rate(rate) = &self.cells else {
            return None;
        };
        let mut gaps = rate.gaps(&self.values);
        Some(CertificateSummary {
            cells: gaps.len(),
            mean_gap: (!gaps.is_empty()).then(|| gaps.iter().sum::<f64>() / gaps.len() as f64),
            max_gap: gaps.iter().copied().max_by(f64::total_cmp),
            median_gap: upper_median(&mut gaps),
        })
    }

    /// Rate maps: the SDR upper bound per cell (flat, like `values`).
    pub fn upper_bound(&self) -> Option<&[f64]> {
        match &self.cells {
            CellSolutions::Gain { .. } => None,
            CellSolutions::Rate(rate) => Some(&rate.upper_bound),
        }
    }
}

/// The element at index n/2 of the values in order (for an even count, the upper middle one),
/// by selection: O(n), where sorting a million values cost more than building the map.
fn upper_median(values: &mut [f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let middle = values.len() / 2;
    Some(*values.select_nth_unstable_by(middle, f64::total_cmp).1)
}

/// η(γ) (paper eq. 44): the share of free cells whose value is at least γ (0 on a floor with
/// no free cell).
pub fn coverage(values: &[f64], occupied: &[bool], threshold: f64) -> f64 {
    let free = occupied.iter().filter(|o| !**o).count();
    if free == 0 {
        return 0.0;
    }
    values.iter().filter(|v| **v >= threshold).count() as f64 / free as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Selection finds what sorting finds: the element at n/2 in order, ties and all.
        #[test]
        fn the_median_by_selection_is_the_sorted_middle(
            mut values in proptest::collection::vec(prop_oneof![-100.0..100.0f64, Just(1.5)], 0..200),
        ) {
            let mut sorted = values.clone();
            sorted.sort_by(f64::total_cmp);
            prop_assert_eq!(upper_median(&mut values), sorted.get(sorted.len() / 2).copied());
        }
    }
}
