//! A built map as its parts: what the build computed per cell, without what the scenario
//! determines (the grid, the channel models, the rate model), so a map can be stored compactly
//! and rebuilt from its scenario (`irs_answers::encoding` writes the parts as bytes).

use super::{CellSolutions, MapKey, MapKind, RadioMap, RateCells};
use crate::channel::ChannelModel;
use crate::rate::RateModel;
use crate::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// The per-cell solutions of a map as stored: gain maps, the serving AP of each cell (only with
/// several APs); rate maps, the upper bound, N phase codes (`u16`, as the map holds them), the
/// power split and the decoding order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum StoredCells {
    /// A gain map: its phases are recomputed from the scenario, so only the serving AP is kept.
    Gain {
        /// The AP serving each cell (flat index i·ny + j); empty with one AP.
        serving: Vec<u8>,
        /// The serving AP's gain (dB) per cell; empty when the AP of best gain serves every
        /// cell.
        serving_gain_db: Vec<f64>,
    },
    /// A rate map: the solver's argmax and the certificate of every cell.
    Rate {
        /// Per cell: the SDR upper bound on the MRU's rate (bit/s/Hz, §5).
        upper_bound: Vec<f64>,
        /// N 16-bit phase codes per cell, θ = 2π·c/2¹⁶ (none for phases `none`).
        phases: Vec<u16>,
        /// K + 1 transmit powers per cell (W), MRU first, then the SRUs in scenario order.
        power_w: Vec<f64>,
        /// Per cell: the decoding order's index into [`RateModel::orders`] (0 for OMA).
        order: Vec<u8>,
    },
}

impl RadioMap {
    /// The per-cell solutions as stored.
    pub fn stored_cells(&self) -> StoredCells {
        match &self.cells {
            CellSolutions::Gain {
                serving,
                serving_gain_db,
                ..
            } => StoredCells::Gain {
                serving: serving.clone(),
                serving_gain_db: serving_gain_db.clone(),
            },
            CellSolutions::Rate(rate) => StoredCells::Rate {
                upper_bound: rate.upper_bound.clone(),
                phases: rate.phases.clone(),
                power_w: rate.power_w.clone(),
                order: rate.order.clone(),
            },
        }
    }

    /// The map of `scenario` that these parts make (the key's scenario must be `scenario`,
    /// which the caller checks by id), rebuilding what the scenario determines. Every length
    /// and index is checked against the scenario, so parts of another scenario are refused with
    /// the reason.
    #[allow(clippy::too_many_arguments)]
    pub fn from_parts(
        scenario: &Scenario,
        key: MapKey,
        id: String,
        build_seconds: f64,
        built_at_unix_s: u64,
        values: Vec<f64>,
        occupied: Vec<bool>,
        stored: StoredCells,
    ) -> Result<RadioMap, String> {
        let mismatch = |what: &str, found: usize, expected: usize| {
            Err(format!(
                "{what}: {found} entries stored, the scenario's grid needs {expected}"
            ))
        };
        let grid = scenario.grid();
        let cells = grid.cells();
        if values.len() != cells {
            return mismatch("values", values.len(), cells);
        }
        if occupied.len() != cells {
            return mismatch("occupied", occupied.len(), cells);
        }
        let solutions = match (key.kind, stored) {
            (
                MapKind::Gain,
                StoredCells::Gain {
                    serving,
                    serving_gain_db,
                },
            ) => {
                let aps = scenario.access_points().len();
                let expected = if aps > 1 { cells } else { 0 };
                if serving.len() != expected {
                    return mismatch("serving", serving.len(), expected);
                }
                if !serving_gain_db.is_empty() && serving_gain_db.len() != cells {
                    return mismatch("serving_gain_db", serving_gain_db.len(), cells);
                }
                if serving.iter().any(|&ap| usize::from(ap) >= aps) {
                    return Err(format!(
                        "a cell is served by an AP the scenario (with {aps}) does not have"
                    ));
                }
                CellSolutions::Gain {
                    models: (0..aps)
                        .map(|ap| Arc::new(ChannelModel::for_ap(scenario, ap)))
                        .collect(),
                    serving,
                    serving_gain_db,
                    antenna_height_m: scenario.mru.antenna_height_m,
                }
            }
            (
                MapKind::Rate,
                StoredCells::Rate {
                    upper_bound,
                    phases,
                    power_w,
                    order,
                },
            ) => {
                let access = key
                    .access
                    .ok_or_else(|| String::from("a rate map's key without an access scheme"))?;
                let channel = ChannelModel::new(scenario);
                let model = RateModel::for_scenario(scenario, access);
                let with_irs = key.phases != crate::phases::PhaseMode::None;
                let n = if with_irs { channel.subsurfaces() } else { 0 };
                if upper_bound.len() != cells {
                    return mismatch("upper_bound", upper_bound.len(), cells);
                }
                if phases.len() != cells * n {
                    return mismatch("phases", phases.len(), cells * n);
                }
                if power_w.len() != cells * model.users() {
                    return mismatch("power_w", power_w.len(), cells * model.users());
                }
                if order.len() != cells {
                    return mismatch("order", order.len(), cells);
                }
                if order
                    .iter()
                    .any(|&o| usize::from(o) >= model.orders().len())
                {
                    return Err("a cell's decoding order is not one of the scenario's".into());
                }
                CellSolutions::Rate(RateCells {
                    upper_bound,
                    subsurfaces: n,
                    surface_lengths: channel.surface_lengths().collect(),
                    phases,
                    power_w,
                    order,
                    model,
                })
            }
            (kind, _) => {
                return Err(format!(
                    "the key says a {kind} map, the cells are of the other kind"
                ));
            }
        };
        Ok(RadioMap {
            id,
            key,
            grid,
            values,
            closed_passages: super::passages::closed_passages(scenario, &grid, &occupied),
            occupied,
            cells: solutions,
            links: super::LinkBudget::for_scenario(scenario),
            build_seconds,
            built_at_unix_s,
        })
    }
}
