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
        let mut finite: Vec<f64> = self
            .values
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        finite.sort_by(f64::total_cmp);
        let free = self.free_cells();
        let pick = |q: f64| {
            finite
                .get(((finite.len() - 1) as f64 * q).round() as usize)
                .copied()
        };
        MapStats {
            cells: self.values.len(),
            free_cells: free,
            occupied_cells: self.values.len() - free,
            closed_passages: self.closed_passages.total,
            valued_cells: finite.len(),
            min: finite.first().copied(),
            max: finite.last().copied(),
            mean: (!finite.is_empty()).then(|| finite.iter().sum::<f64>() / finite.len() as f64),
            median: if finite.is_empty() { None } else { pick(0.5) },
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
        gaps.sort_by(f64::total_cmp);
        Some(CertificateSummary {
            cells: gaps.len(),
            median_gap: (!gaps.is_empty()).then(|| gaps[gaps.len() / 2]),
            mean_gap: (!gaps.is_empty()).then(|| gaps.iter().sum::<f64>() / gaps.len() as f64),
            max_gap: gaps.last().copied(),
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

/// η(γ) (paper eq. 44): the share of free cells whose value is at least γ (0 on a floor with
/// no free cell).
pub fn coverage(values: &[f64], occupied: &[bool], threshold: f64) -> f64 {
    let free = occupied.iter().filter(|o| !**o).count();
    if free == 0 {
        return 0.0;
    }
    values.iter().filter(|v| **v >= threshold).count() as f64 / free as f64
}
