//! The pieces a scenario document is made of, as parsed (docs/model.md §1): the room, the grid
//! spacing, boxes and walls on the floor, access points, IRSs, the robots and the channel.

use crate::input::present;
use serde::{Deserialize, Serialize};

/// The floor's rectangle and its height (m); its walls are the rectangle's sides.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Room {
    /// West wall, the x of the first column of cell centres (m).
    pub x_min: f64,
    /// East wall, the x of the last column of cell centres (m).
    pub x_max: f64,
    /// South wall (m).
    pub y_min: f64,
    /// North wall (m).
    pub y_max: f64,
    /// Height of the ceiling above the floor (m); every device and obstacle lies below it.
    pub ceiling_m: f64,
}

/// The grid's spacing, as the document gives it (the lattice itself is [`super::Grid`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridSpec {
    /// Δ = Δx = Δy (m).
    pub resolution_m: f64,
}

/// An axis-aligned box standing on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Obstacle {
    /// Centre of its footprint, [x, y] (m).
    pub center: [f64; 2],
    /// Sides of its footprint along x and y (m).
    pub size: [f64; 2],
    /// Height above the floor (m).
    pub height_m: f64,
}

/// A straight wall from `from` to `to` (its centre line), standing on the floor.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    /// One end of the centre line, [x, y] (m).
    pub from: [f64; 2],
    /// The other end of the centre line, [x, y] (m).
    pub to: [f64; 2],
    /// Thickness across the centre line (m).
    pub thickness_m: f64,
    /// Height above the floor (m).
    pub height_m: f64,
}

/// An access point, each on its own channel (docs/model.md §3).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AccessPoint {
    /// Antenna position [x, y, z] (m).
    pub position: [f64; 3],
    /// P_max (dBm).
    pub tx_power_dbm: f64,
    /// σ², the receiver noise power of every robot (dBm).
    pub noise_dbm: f64,
    /// f_c (GHz).
    pub carrier_ghz: f64,
    /// The AP antenna's gain towards the robots (dBi), added to the link budget of received
    /// power, SNR and rates (docs/model.md §3.1); the channel gain map does not include it. Left
    /// out of the canonical form at 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub antenna_gain_dbi: f64,
    /// The channel's bandwidth (MHz), which turns bit/s/Hz into Mbit/s; needed only for
    /// throughput (`mbps`) thresholds and values.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bandwidth_mhz: Option<f64>,
}

/// How the N̄ elements of a sub-surface combine (docs/model.md §2).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Grouping {
    /// w̃_n = N̄ × the cascaded LoS coefficient at the sub-surface centre.
    #[default]
    Coherent,
    /// Each element at its own position; w̃_n sums the N̄ element coefficients.
    Elements,
}

/// An intelligent reflecting surface on a wall (docs/model.md §2): N = nx_sub · nz_sub
/// sub-surfaces of N̄ elements each, phased per sub-surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Irs {
    /// Centre of the surface [x, y, z] (m), on a wall face.
    pub center: [f64; 3],
    /// Unit vector pointing into the room.
    pub normal: [f64; 3],
    /// Sub-surfaces along the wall's horizontal axis.
    pub nx_sub: usize,
    /// Sub-surfaces along the wall's vertical axis.
    pub nz_sub: usize,
    /// N̄, elements per sub-surface (M = N·N̄).
    pub elements_per_sub: usize,
    /// Centre-to-centre spacing of sub-surfaces (m); default λ/2.
    #[serde(default, deserialize_with = "present")]
    pub sub_pitch_m: Option<f64>,
    /// How the elements of a sub-surface combine (default `coherent`).
    #[serde(default)]
    pub grouping: Grouping,
    /// Spacing of the elements of one sub-surface, laid out in a row along the wall's horizontal
    /// axis (`elements` grouping only); default `sub_pitch_m / N̄`, so the row tiles the
    /// sub-surface.
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    pub element_pitch_m: Option<f64>,
    /// Mount the surface on the nearest wall, obstacle side or floor-plan edge within this
    /// distance (m, horizontal, at most 5) that faces the way `normal` does; `center` and
    /// `normal` become the mounted pose (docs/scenarios.md, "Mounting a surface"). Only read:
    /// the scenario keeps the mounted pose, not this field, so it never reaches the canonical
    /// form.
    #[serde(
        default,
        deserialize_with = "present",
        skip_serializing_if = "Option::is_none"
    )]
    pub mount_within_m: Option<f64>,
}

impl Irs {
    /// N, the number of independently phased sub-surfaces.
    pub fn subsurfaces(&self) -> usize {
        self.nx_sub * self.nz_sub
    }
    /// M = N · N̄, the number of reflecting elements.
    pub fn elements(&self) -> usize {
        self.subsurfaces() * self.elements_per_sub
    }
    /// Width along the wall (m): `nx_sub` tiles of `sub_pitch_m` (0 before defaults resolve).
    pub fn width_m(&self) -> f64 {
        self.nx_sub as f64 * self.sub_pitch_m.unwrap_or(0.0)
    }
    /// Height up the wall (m): `nz_sub` tiles of `sub_pitch_m` (0 before defaults resolve).
    pub fn height_m(&self) -> f64 {
        self.nz_sub as f64 * self.sub_pitch_m.unwrap_or(0.0)
    }
}

/// The mobile robot (MRU) whose path is planned.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mru {
    /// H_0 (m).
    pub antenna_height_m: f64,
    /// V_max (m/s).
    pub v_max_mps: f64,
    /// The robot's radius (m), by which obstacles are inflated before cells are marked
    /// occupied (docs/model.md §1), as Nav2 inflates its costmap. Left out of the canonical
    /// form at 0, so scenarios written before it keep their ids.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub radius_m: f64,
}

fn is_zero(value: &f64) -> bool {
    *value == 0.0
}

/// A static robot (SRU) sharing the AP with the MRU; rate maps guarantee it its rate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sru {
    /// Antenna position [x, y, z] (m).
    pub position: [f64; 3],
    /// r̄_s (bit/s/Hz).
    pub min_rate_bps_hz: f64,
}

/// The path-loss model of every link (docs/model.md §1).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum PathLossModel {
    /// 3GPP TR 38.901 indoor factory, sparse clutter, high BS (paper Section IV).
    #[default]
    #[serde(rename = "3gpp_inf_sh")]
    ThreeGppInfSh,
}

/// The channel's parameters, shared by every link.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ChannelSpec {
    /// κ (dB), the Rician factor of every LoS link.
    #[serde(default = "default_rician_k_db")]
    pub rician_k_db: f64,
    /// The path-loss model (default and only one: `3gpp_inf_sh`).
    #[serde(default)]
    pub path_loss: PathLossModel,
    /// G_rx (dBi), the receive antenna gain of every robot (like `noise_dbm`, one value for the
    /// moving and the static robots), added to every link budget (docs/model.md §3.1). Left out
    /// of the canonical form at 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub rx_antenna_gain_dbi: f64,
    /// A fade margin (dB) taken off every link budget (received power, SNR, rates; not the
    /// channel gain), so that thresholds hold with that much to spare. Left out of the canonical
    /// form at 0.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub fade_margin_db: f64,
}

fn default_rician_k_db() -> f64 {
    3.0
}

impl Default for ChannelSpec {
    fn default() -> Self {
        ChannelSpec {
            rician_k_db: default_rician_k_db(),
            path_loss: PathLossModel::default(),
            rx_antenna_gain_dbi: 0.0,
            fade_margin_db: 0.0,
        }
    }
}
