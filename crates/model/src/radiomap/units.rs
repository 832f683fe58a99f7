//! A map's values in the units a fleet operator specifies a link in (docs/model.md §3.1): channel
//! gain (dB, the map's own on gain maps), received power (dBm), SNR (dB), spectral efficiency
//! (bit/s/Hz, the rate maps' own) and throughput (Mbit/s).
//!
//! Every unit but the gain follows from the serving AP's link budget: received power
//! P_r = G + P + G_tx + G_rx − M (dBm), with G the serving AP's channel gain (dB), P its transmit
//! power, G_tx and G_rx the antenna gains and M the fade margin; SNR = P_r − σ² (dB); spectral
//! efficiency log₂(1 + SNR) (the rate of eq. 26 for one user); throughput B × that (Mbit/s, B in
//! MHz). Each is a strictly increasing function of G for one AP, so a threshold in any unit
//! selects the same cells as the corresponding gain threshold would for that AP.

use super::{CellSolutions, MapKind, RadioMap};
use crate::input::FieldError;
use crate::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::str::FromStr;

/// The unit of a threshold and of the values reported with it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Unit {
    /// Channel power gain (dB): the best AP's, as gain maps hold it.
    GainDb,
    /// Received power from the serving AP (dBm).
    Dbm,
    /// Signal-to-noise ratio at the serving AP's noise power (dB).
    SnrDb,
    /// Spectral efficiency (bit/s/Hz): log₂(1 + SNR) on gain maps, the MRU's rate on rate maps.
    BpsHz,
    /// Throughput (Mbit/s): the spectral efficiency times the serving AP's bandwidth.
    Mbps,
}

impl Unit {
    /// Every unit, in the order of this enum.
    pub const ALL: [Unit; 5] = [
        Unit::GainDb,
        Unit::Dbm,
        Unit::SnrDb,
        Unit::BpsHz,
        Unit::Mbps,
    ];

    /// The name a request gives (`gain_db`, `dbm`, `snr_db`, `bps_hz`, `mbps`).
    pub fn name(self) -> &'static str {
        match self {
            Unit::GainDb => "gain_db",
            Unit::Dbm => "dbm",
            Unit::SnrDb => "snr_db",
            Unit::BpsHz => "bps_hz",
            Unit::Mbps => "mbps",
        }
    }

    /// The symbol an answer labels its values with (`dB`, `dBm`, `dB SNR`, `bit/s/Hz`,
    /// `Mbit/s`).
    pub fn symbol(self) -> &'static str {
        match self {
            Unit::GainDb => "dB",
            Unit::Dbm => "dBm",
            Unit::SnrDb => "dB SNR",
            Unit::BpsHz => "bit/s/Hz",
            Unit::Mbps => "Mbit/s",
        }
    }

    /// The unit a map of `kind` holds its values in.
    pub fn native(kind: MapKind) -> Unit {
        match kind {
            MapKind::Gain => Unit::GainDb,
            MapKind::Rate => Unit::BpsHz,
        }
    }
}

impl FromStr for Unit {
    type Err = String;
    fn from_str(s: &str) -> Result<Unit, String> {
        Unit::ALL
            .into_iter()
            .find(|u| u.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = Unit::ALL.iter().map(|u| u.name()).collect();
                format!("expected one of {}, got {s:?}", names.join(", "))
            })
    }
}

/// One AP's link budget: what turns its channel gain into received power, SNR and throughput.
#[derive(Debug, Clone, PartialEq)]
pub struct LinkBudget {
    /// P + G_tx + G_rx − M (dBm): the power received through a channel gain of 0 dB.
    pub offset_dbm: f64,
    /// σ² (dBm).
    pub noise_dbm: f64,
    /// B (MHz), if the scenario states it.
    pub bandwidth_mhz: Option<f64>,
    /// The AP's JSON path in the scenario (`ap` or `aps[k]`), for errors.
    pub field: String,
}

impl LinkBudget {
    /// The link budget of every AP of a scenario, in scenario order.
    pub fn for_scenario(scenario: &Scenario) -> Vec<LinkBudget> {
        let common = scenario.channel.rx_antenna_gain_dbi - scenario.channel.fade_margin_db;
        scenario
            .access_points()
            .iter()
            .enumerate()
            .map(|(k, ap)| LinkBudget {
                offset_dbm: ap.tx_power_dbm + ap.antenna_gain_dbi + common,
                noise_dbm: ap.noise_dbm,
                bandwidth_mhz: ap.bandwidth_mhz,
                field: scenario.ap_field(k),
            })
            .collect()
    }

    /// A gain (dB) through this AP in one of the link budget's units (dBm, SNR, bit/s/Hz,
    /// Mbit/s; a gain stays a gain). NaN stays NaN.
    pub(crate) fn convert_gain_db(&self, unit: Unit, gain_db: f64) -> f64 {
        let snr_db = gain_db + self.offset_dbm - self.noise_dbm;
        match unit {
            // Not reached: a gain map gives its own values in dB (the best AP's gain).
            Unit::GainDb => gain_db,
            Unit::Dbm => gain_db + self.offset_dbm,
            Unit::SnrDb => snr_db,
            Unit::BpsHz => spectral_efficiency(snr_db),
            // Checked present by `RadioMap::values_in` before any cell is converted.
            Unit::Mbps => self.bandwidth_mhz.unwrap_or(f64::NAN) * spectral_efficiency(snr_db),
        }
    }
}

impl LinkBudget {
    /// The channel gain (dB) through this AP at which a value in `unit` is reached: the inverse
    /// of [`LinkBudget::convert_gain_db`], so a requirement in any unit becomes a gain threshold
    /// per AP. A rate of 0 or less is met by every gain (−∞). Mbit/s needs the AP's bandwidth
    /// (NaN without it; callers check first, as [`RadioMap::values_in`] does).
    pub(crate) fn gain_db_for(&self, unit: Unit, value: f64) -> f64 {
        let from_snr = |snr_db: f64| snr_db - self.offset_dbm + self.noise_dbm;
        // SNR = 2^r − 1, written with exp_m1 so small rates keep their digits.
        let from_rate = |r: f64| {
            if r <= 0.0 {
                f64::NEG_INFINITY
            } else {
                from_snr(10.0 * (r * std::f64::consts::LN_2).exp_m1().log10())
            }
        };
        match unit {
            Unit::GainDb => value,
            Unit::Dbm => value - self.offset_dbm,
            Unit::SnrDb => from_snr(value),
            Unit::BpsHz => from_rate(value),
            Unit::Mbps => from_rate(value / self.bandwidth_mhz.unwrap_or(f64::NAN)),
        }
    }
}

/// log₂(1 + SNR) for an SNR in dB; ln_1p keeps it accurate at very low SNR, where 1 + SNR
/// would round to 1.
fn spectral_efficiency(snr_db: f64) -> f64 {
    (snr_db * (std::f64::consts::LN_10 / 10.0)).exp().ln_1p() / std::f64::consts::LN_2
}

impl RadioMap {
    /// The unit of [`RadioMap::values`].
    pub fn native_unit(&self) -> Unit {
        Unit::native(self.key.kind)
    }

    /// Every cell's value in `unit` (NaN where occupied): the map's own values for its native
    /// unit, otherwise converted through the serving AP's link budget. A gain map answers every
    /// unit; a rate map, whose values are already rates, answers `bps_hz` and `mbps`. Errors
    /// name the request's `unit` field and what the scenario lacks.
    pub fn values_in(&self, unit: Unit) -> Result<Cow<'_, [f64]>, FieldError> {
        if unit == self.native_unit() {
            return Ok(Cow::Borrowed(&self.values));
        }
        if unit == Unit::Mbps
            && let Some(missing) = self.links.iter().find(|l| l.bandwidth_mhz.is_none())
        {
            return Err(FieldError::new(
                "unit",
                format!(
                    "throughput needs the channel's bandwidth: give {}.bandwidth_mhz in the scenario",
                    missing.field
                ),
            ));
        }
        match &self.cells {
            CellSolutions::Rate(_) => match unit {
                Unit::Mbps => {
                    let b = self.links[0].bandwidth_mhz.unwrap_or(f64::NAN);
                    Ok(Cow::Owned(self.values.iter().map(|v| v * b).collect()))
                }
                _ => Err(FieldError::new(
                    "unit",
                    format!(
                        "a rate map holds rates: ask in bps_hz or mbps, not {} (gain maps answer \
                         every unit)",
                        unit.name()
                    ),
                )),
            },
            CellSolutions::Gain {
                serving,
                serving_gain_db,
                ..
            } => {
                // The serving AP's gain: the map's value unless another AP (with a stronger
                // budget) serves the cell.
                let gains = if serving_gain_db.is_empty() {
                    &self.values
                } else {
                    serving_gain_db
                };
                Ok(Cow::Owned(
                    gains
                        .iter()
                        .enumerate()
                        .map(|(c, &g)| {
                            let ap = serving.get(c).map_or(0, |&k| usize::from(k));
                            self.links[ap].convert_gain_db(unit, g)
                        })
                        .collect(),
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn units_parse_by_name_and_name_themselves() {
        for unit in Unit::ALL {
            assert_eq!(unit.name().parse::<Unit>(), Ok(unit));
            let json = serde_json::to_string(&unit).unwrap();
            assert_eq!(json, format!("\"{}\"", unit.name()));
        }
        assert!("dBm".parse::<Unit>().unwrap_err().contains("dbm"));
    }

    /// The worked example of docs/model.md §3.1: −80 dB of gain, 20 dBm, antennas of 3 and
    /// 2 dBi, a 5 dB margin and −94 dBm of noise give −60 dBm, 34 dB of SNR, 11.29 bit/s/Hz
    /// and 225.9 Mbit/s over 20 MHz.
    #[test]
    fn the_worked_example_converts_as_documented() {
        let link = LinkBudget {
            offset_dbm: 20.0 + 3.0 + 2.0 - 5.0,
            noise_dbm: -94.0,
            bandwidth_mhz: Some(20.0),
            field: "ap".into(),
        };
        assert_eq!(link.convert_gain_db(Unit::Dbm, -80.0), -60.0);
        assert_eq!(link.convert_gain_db(Unit::SnrDb, -80.0), 34.0);
        let se = (1.0 + 10f64.powf(3.4)).log2();
        assert!((link.convert_gain_db(Unit::BpsHz, -80.0) - se).abs() < 1e-12);
        assert!((se - 11.2951).abs() < 1e-4, "{se}");
        assert!((link.convert_gain_db(Unit::Mbps, -80.0) - 20.0 * se).abs() < 1e-10);
        assert!(link.convert_gain_db(Unit::Dbm, f64::NAN).is_nan());
        // At −40 dB of SNR, log₂(1 + 10⁻⁴) to full relative precision.
        let low = spectral_efficiency(-40.0);
        assert!((low / (1e-4f64.ln_1p() / std::f64::consts::LN_2) - 1.0).abs() < 1e-14);
    }

    /// A requirement in any unit turns back into the gain that meets it exactly.
    #[test]
    fn a_requirement_inverts_to_its_gain() {
        let link = LinkBudget {
            offset_dbm: 20.0,
            noise_dbm: -94.0,
            bandwidth_mhz: Some(20.0),
            field: "ap".into(),
        };
        for unit in Unit::ALL {
            for gain in [-120.0, -80.0, -61.5, -40.0] {
                let value = link.convert_gain_db(unit, gain);
                let back = link.gain_db_for(unit, value);
                assert!(
                    (back - gain).abs() < 1e-9,
                    "{unit:?} {gain} → {value} → {back}"
                );
            }
        }
        assert_eq!(link.gain_db_for(Unit::BpsHz, 0.0), f64::NEG_INFINITY);
    }
}
