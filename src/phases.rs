//! How the IRS phases are chosen (docs/model.md §3): continuously, with b-bit phase shifters,
//! or not at all, and the quantisation of eq. 11's optimal phases to b bits (eq. 43).

use crate::channel::ChannelModel;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

/// Largest phase-shifter resolution accepted for `bits` (2^16 levels is continuous in practice).
pub const MAX_PHASE_BITS: u8 = 16;

/// How the IRS phases are chosen.
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

/// The phases of a mode at `user`: θ* of eq. 11, quantised for `bits` to the nearest of
/// L = 2^b levels modulo 2π (eq. 43). All phases land in [0, 2π).
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantisation_wraps_modulo_two_pi() {
        assert_eq!(quantise_phase(TAU - 0.01, 1), 0.0);
        assert!((quantise_phase(3.0, 1) - std::f64::consts::PI).abs() < 1e-15);
        assert!((quantise_phase(1.0, 2) - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    }

    #[test]
    fn names_round_trip() {
        assert!("0".parse::<PhaseMode>().is_err());
        assert_eq!("3".parse::<PhaseMode>(), Ok(PhaseMode::Bits(3)));
        for mode in [PhaseMode::Continuous, PhaseMode::None, PhaseMode::Bits(16)] {
            assert_eq!(mode.to_string().parse::<PhaseMode>(), Ok(mode));
        }
    }
}
