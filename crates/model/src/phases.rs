//! How the IRS phases are chosen (docs/model.md §3): continuously, with b-bit phase shifters,
//! or not at all, and the quantisation of eq. 11's optimal phases to b bits (eq. 43).

use crate::channel::ChannelModel;
use crate::input::Scalar;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

/// Largest phase-shifter resolution accepted for `bits` (2^16 levels is continuous in practice).
pub const MAX_PHASE_BITS: u8 = 16;

/// How the IRS phases are chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PhaseMode {
    /// Any phase in [0, 2π): eq. 11's θ* exactly, the gain in closed form (eq. 12).
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
        match crate::input::deserialize_scalar(d)? {
            Scalar::Text(s) => s.parse().map_err(serde::de::Error::custom),
            Scalar::Number(_, text) => text.parse().map_err(serde::de::Error::custom),
            Scalar::Other(other) => Err(serde::de::Error::custom(format!(
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

/// Levels of a stored phase code: 2^16, so a code is one `u16`.
const CODE_LEVELS: f64 = 65_536.0;

/// A phase in [0, 2π) as the nearest of 2^16 levels (a rate map's per-cell phases are stored so:
/// 2 bytes instead of 8). The decoded phase is within π/2^16 ≈ 4.8 × 10⁻⁵ rad of θ; the phases
/// of a `bits` map (b ≤ [`MAX_PHASE_BITS`] = 16) are levels of this grid and round-trip exactly.
/// docs/model.md §5 states what the error costs in rate (≤ 10⁻⁶ bit/s/Hz, tested).
///
/// Nearest with ties away from zero, written without libm's `fmod` and `round` (calls on the
/// baseline target, and most of a path answer's time in codes): θ already in [0, 2π), as
/// every phase this crate makes is, is its own remainder, and x − ⌊x⌋ is exact for
/// 0 ≤ x ≤ 2¹⁶. Inlined across crates: the answers crate writes a path's codes in a loop.
#[inline]
pub fn encode_phase(theta: f64) -> u16 {
    let theta = if (0.0..TAU).contains(&theta) {
        theta
    } else {
        theta.rem_euclid(TAU)
    };
    let levels = theta / TAU * CODE_LEVELS;
    let below = levels as u32;
    let nearest = if levels - f64::from(below) >= 0.5 {
        below + 1
    } else {
        below
    };
    // 2¹⁶ levels is 2π again: code 0.
    (nearest % (CODE_LEVELS as u32)) as u16
}

/// The phase of a code of [`encode_phase`], in [0, 2π).
#[inline]
pub fn decode_phase(code: u16) -> f64 {
    f64::from(code) * (TAU / CODE_LEVELS)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same codes as the libm formula it replaces, on random phases, near level
    /// boundaries and outside [0, 2π).
    #[test]
    fn phase_codes_match_the_libm_formula() {
        let reference =
            |t: f64| ((t.rem_euclid(TAU) / TAU * CODE_LEVELS).round() % CODE_LEVELS) as u16;
        let mut theta = -20.0;
        while theta < 20.0 {
            assert_eq!(encode_phase(theta), reference(theta), "{theta}");
            theta += 0.000_377;
        }
        for k in 0..=65536u32 {
            for offset in [-1e-12, 0.0, 1e-12] {
                let t = (f64::from(k) + 0.5 + offset) * (TAU / CODE_LEVELS);
                if t < TAU {
                    assert_eq!(encode_phase(t), reference(t), "{t}");
                }
            }
        }
        assert_eq!(encode_phase(TAU - 1e-12), 0);
    }

    #[test]
    fn phase_codes_are_within_half_a_level_and_exact_on_bit_grids() {
        let half_level = TAU / CODE_LEVELS / 2.0;
        for k in 0..10_000 {
            let theta = k as f64 * 0.000_731 - 1.0;
            let back = decode_phase(encode_phase(theta));
            let wrapped = (back - theta.rem_euclid(TAU) + TAU / 2.0).rem_euclid(TAU) - TAU / 2.0;
            assert!(
                wrapped.abs() <= half_level * (1.0 + 1e-9),
                "{theta}: {back}"
            );
            assert!((0.0..TAU).contains(&back));
        }
        assert_eq!(encode_phase(TAU - 1e-9), 0);
        for bits in 1..=MAX_PHASE_BITS {
            for theta in [0.3, 1.7, 4.4, 6.2] {
                let level = quantise_phase(theta, bits);
                assert_eq!(
                    decode_phase(encode_phase(level)),
                    level,
                    "{bits} bits, {theta}"
                );
            }
        }
    }

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
