//! How a waypoint's IRS phases are carried and written: as radians, as radians already written
//! as JSON decimals at a chosen precision, or as 16-bit codes in base64.
//!
//! A path answer is mostly phases (the paper map's path: 2 460 of them), so how they are written
//! decides most of its size and of the server's time on it. Writing decimals goes straight
//! from each phase to its digits in one pass: θ is rounded once to an integer number of steps
//! of 10⁻ᵈ rad and that integer's digits are the text. Going through a rounded f64 and a
//! general float formatter, number by number, was a quarter of the server's CPU on path queries
//! (perf, paper map, 16 connections, every query new).

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use serde::{Deserialize, Serialize};
use serde_json::value::RawValue;
use std::f64::consts::TAU;
use std::str::FromStr;

use irs_model::vecmath::ROUNDING_SHIFT;

/// The phase vector θ of one configuration, one vector per IRS in scenario order (N_s values
/// each; none for phases `none`), in radians or as the compact codes a path answer may be
/// asked for ([`PhaseFormat`]).
#[derive(Debug, Clone, Serialize)]
pub enum SurfacePhases {
    /// θ in [0, 2π).
    #[serde(rename = "irs_phases_rad")]
    Radians(Vec<Vec<f64>>),
    /// The same JSON array of arrays as `Radians`, written by [`SurfacePhases::to_decimals`]
    /// with each phase rounded to d decimals: kept as text, so serialising it is one copy.
    #[serde(rename = "irs_phases_rad")]
    Decimals(Box<RawValue>),
    /// Each surface's phases as 16-bit codes c, θ = 2π·c/2¹⁶ ([`irs_model::phases::encode_phase`],
    /// within π/2¹⁶ of the phase), little-endian, two bytes a phase, in base64 (RFC 4648 with
    /// padding): 2.7 characters a phase against 6–7 for a decimal at 10⁻⁴ rad.
    #[serde(rename = "irs_phase_codes")]
    Codes(Vec<String>),
}

/// Equal when they carry the same text (decimals) or the same values.
impl PartialEq for SurfacePhases {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (SurfacePhases::Radians(a), SurfacePhases::Radians(b)) => a == b,
            (SurfacePhases::Decimals(a), SurfacePhases::Decimals(b)) => a.get() == b.get(),
            (SurfacePhases::Codes(a), SurfacePhases::Codes(b)) => a == b,
            _ => false,
        }
    }
}

/// Most decimals [`SurfacePhases::to_decimals`] writes: 10⁻⁹ rad is far below any phase
/// shifter's resolution, and keeps k = θ·10⁹ < 2π·10⁹ an exact integer in a double.
pub const MAX_PHASE_DECIMALS: u32 = 9;

impl SurfacePhases {
    /// The same phases as codes (exact for phases already on the 2π/2¹⁶ grid: rate maps, `bits`).
    pub fn to_codes(&self) -> SurfacePhases {
        let surfaces = match self {
            SurfacePhases::Codes(_) => return self.clone(),
            SurfacePhases::Decimals(_) => &self.radians(),
            SurfacePhases::Radians(surfaces) => surfaces,
        };
        SurfacePhases::Codes(
            surfaces
                .iter()
                .map(|phases| {
                    let mut bytes = Vec::with_capacity(2 * phases.len());
                    for &theta in phases {
                        bytes.extend_from_slice(
                            &irs_model::phases::encode_phase(theta).to_le_bytes(),
                        );
                    }
                    BASE64.encode(bytes)
                })
                .collect(),
        )
    }

    /// Radians written as JSON text, each θ ∈ [0, 2π) rounded to the nearest multiple of
    /// 10^−`decimals` (ties to even; error ≤ ½·10^−`decimals` rad) and written as that decimal
    /// without trailing zeros ("4.7124", "3.5", "0.0"): the shortest text that reads back to
    /// the nearest double, what serde_json writes for that double too (except below 10⁻⁵,
    /// which it writes in exponent form and this in plain decimals). A phase rounding up to 2π
    /// is written as 0, staying in [0, 2π). Other forms are returned as they are.
    ///
    /// # Panics
    /// If `decimals` is 0 or above [`MAX_PHASE_DECIMALS`] (a caller's constant, not input).
    pub fn to_decimals(&self, decimals: u32) -> SurfacePhases {
        let SurfacePhases::Radians(surfaces) = self else {
            return self.clone();
        };
        let write: fn(&[f64], &mut [u8]) -> usize = match decimals {
            1 => write_surface::<1>,
            2 => write_surface::<2>,
            3 => write_surface::<3>,
            4 => write_surface::<4>,
            5 => write_surface::<5>,
            6 => write_surface::<6>,
            7 => write_surface::<7>,
            8 => write_surface::<8>,
            9 => write_surface::<9>,
            _ => panic!("phase decimals must lie in 1..={MAX_PHASE_DECIMALS}, got {decimals}"),
        };
        let phases: usize = surfaces.iter().map(Vec::len).sum();
        // The longest the text can be: "d.", the digits and a comma a phase; two brackets and
        // a comma a surface; the outer brackets. Written by index, then cut to its length.
        let mut text = vec![0u8; 2 + phases * (decimals as usize + 3) + surfaces.len() * 3];
        text[0] = b'[';
        let mut at = 1;
        for (s, surface) in surfaces.iter().enumerate() {
            if s > 0 {
                text[at] = b',';
                at += 1;
            }
            at += write(surface, &mut text[at..]);
        }
        text[at] = b']';
        text.truncate(at + 1);
        let text = String::from_utf8(text).expect("digits, points, commas and brackets are ASCII");
        // SAFETY: `text` is one JSON array of arrays of numbers, no whitespace around it, built
        // above from digits, '.', ',' and brackets only (debug builds re-parse it to check).
        SurfacePhases::Decimals(unsafe { RawValue::from_string_unchecked(text) })
    }

    /// Every surface's phases in radians (decimals read back, codes decoded).
    pub fn radians(&self) -> Vec<Vec<f64>> {
        match self {
            SurfacePhases::Radians(surfaces) => surfaces.clone(),
            SurfacePhases::Decimals(text) => {
                serde_json::from_str(text.get()).expect("decimals this module wrote")
            }
            SurfacePhases::Codes(surfaces) => surfaces
                .iter()
                .map(|text| {
                    let bytes = BASE64.decode(text).expect("codes this module wrote");
                    bytes
                        .chunks_exact(2)
                        .map(|pair| {
                            irs_model::phases::decode_phase(u16::from_le_bytes([pair[0], pair[1]]))
                        })
                        .collect()
                })
                .collect(),
        }
    }

    /// Bytes of JSON these phases take in an answer, near enough to size its buffer.
    pub fn json_len_hint(&self) -> usize {
        match self {
            // The shortest decimal of a phase is up to 18 characters.
            SurfacePhases::Radians(surfaces) => surfaces.iter().map(|s| 2 + 19 * s.len()).sum(),
            SurfacePhases::Decimals(text) => text.get().len(),
            SurfacePhases::Codes(surfaces) => surfaces.iter().map(|s| 3 + s.len()).sum(),
        }
    }
}

/// How finely a path answer's IRS phases are written. A phase written with 17 significant
/// digits is ≈ 20 bytes of JSON and most of a path answer (the paper map's path: 49.6 kB in
/// full, 21.1 kB at the default); no IRS resolves anything near that: 2-bit to 8-bit surfaces
/// have steps of 1.57 to 0.025 rad, and a phase error ε costs at most a factor cos ε of a
/// reflected term's amplitude, 1 − 1.25·10⁻⁹ (10⁻⁸ dB) at the default ε ≤ 5·10⁻⁵ rad. A rate
/// map's phases are already stored to 2π/2¹⁶ (`phases::encode_phase`), so for them `1e-6` and
/// `full` write the stored phases. Rounded phases are written by
/// [`SurfacePhases::to_decimals`], straight from θ to digits.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
pub enum PhasePrecision {
    /// Rounded to 2 decimals (error ≤ 0.005 rad).
    #[serde(rename = "1e-2")]
    Centi,
    /// Rounded to 3 decimals (error ≤ 5·10⁻⁴ rad).
    #[serde(rename = "1e-3")]
    Milli,
    /// Rounded to 4 decimals (error ≤ 5·10⁻⁵ rad), the default.
    #[default]
    #[serde(rename = "1e-4")]
    TenthMilli,
    /// Rounded to 6 decimals (error ≤ 5·10⁻⁷ rad).
    #[serde(rename = "1e-6")]
    Micro,
    /// Every bit of the f64 (the shortest decimal that reads back to the same number).
    #[serde(rename = "full")]
    Full,
}

impl PhasePrecision {
    /// Decimals kept, `None` for full precision.
    pub(crate) fn decimals(self) -> Option<u32> {
        match self {
            PhasePrecision::Centi => Some(2),
            PhasePrecision::Milli => Some(3),
            PhasePrecision::TenthMilli => Some(4),
            PhasePrecision::Micro => Some(6),
            PhasePrecision::Full => None,
        }
    }
}

impl FromStr for PhasePrecision {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        irs_model::input::parse_name(s)
    }
}

/// How a path answer writes its IRS phases: decimals in radians (`irs_phases_rad`, rounded to
/// a [`PhasePrecision`]), or 16-bit codes in base64 (`irs_phase_codes`,
/// [`SurfacePhases::Codes`]): within π/2¹⁶ ≈ 4.8·10⁻⁵ rad, as fine as the default 10⁻⁴ rad,
/// in 2.7 characters a phase instead of 6–7, and directly the levels a b-bit surface
/// controller takes (c >> (16 − b)).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PhaseFormat {
    /// Decimals in radians (`irs_phases_rad`), rounded to the [`PhasePrecision`]; the default.
    #[default]
    Radians,
    /// 16-bit codes c, θ = 2π·c/2¹⁶: one base64 string of little-endian codes a surface
    /// (`irs_phase_codes`).
    Codes,
}

impl FromStr for PhaseFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        irs_model::input::parse_name(s)
    }
}

/// "00", "01", …, "99": two digits of a number per lookup, half the divisions of one at a time.
const DIGIT_PAIRS: &[u8; 200] = b"\
0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// One surface's phases as a JSON array of decimals with at most `D` places (see
/// [`SurfacePhases::to_decimals`]) at the start of `out`, which has room for D + 3 bytes a
/// phase and two brackets; returns the bytes written. `D` is a constant so that the powers of
/// ten are too and the divisions below become multiplications.
fn write_surface<const D: u32>(phases: &[f64], out: &mut [u8]) -> usize {
    let scale = 10u64.pow(D);
    let scale_f64 = scale as f64;
    // The first step count whose decimal is ≥ 2π (6.29 at two decimals, 6.2832 at four).
    let wrap = (TAU * scale_f64).ceil() as u64;
    // "w." and the D digits of the fraction.
    let full = D as usize + 2;
    out[0] = b'[';
    let mut at = 1;
    for (n, &theta) in phases.iter().enumerate() {
        debug_assert!((0.0..TAU).contains(&theta), "phase {theta} outside [0, 2π)");
        if n > 0 {
            out[at] = b',';
            at += 1;
        }
        // To the nearest integer: inline, where `round` is a libm call on the baseline target.
        // (Through i64, one instruction, where a conversion to u64 is several on x86-64.)
        let steps = ((theta * scale_f64 + ROUNDING_SHIFT) - ROUNDING_SHIFT) as i64 as u64;
        let steps = if steps >= wrap { 0 } else { steps };
        // The whole part is a single digit, as steps < wrap ≤ 6.3·10ᴰ; the fraction's digits
        // go two at a time from the right.
        let number = &mut out[at..at + full];
        number[0] = b'0' + (steps / scale) as u8;
        number[1] = b'.';
        let mut fraction = steps % scale;
        let mut end = full;
        while end >= 4 {
            let pair = 2 * (fraction % 100) as usize;
            number[end - 2..end].copy_from_slice(&DIGIT_PAIRS[pair..pair + 2]);
            fraction /= 100;
            end -= 2;
        }
        if end == 3 {
            number[2] = b'0' + fraction as u8;
        }
        // The fraction's trailing zeros dropped, one digit kept ("3.0"): the next byte
        // written overwrites them. (Most phases have none: a well-predicted loop, faster
        // here than counting them with D − 1 divisibility tests.)
        let trailing = number[3..].iter().rev().take_while(|&&d| d == b'0').count();
        at += full - trailing;
    }
    out[at] = b']';
    at + 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::format_phases;
    use irs_model::planner::{Endpoint, PathAnswer, Waypoint};
    use irs_model::radiomap::CellConfig;

    /// Each precision writes its number of decimals (the writer itself is tested in
    /// radiomap::phase_text); `full` keeps every bit; codes are codes.
    #[test]
    fn write_phases_applies_the_precision_asked_for() {
        let theta = 4.71238898038469;
        let answer = |format, precision| {
            let end = Endpoint {
                requested: [0.0, 0.0],
                x: 0.0,
                y: 0.0,
                i: 0,
                j: 0,
                snapped: false,
                moved: false,
                node: None,
            };
            let path = PathAnswer {
                map_id: String::new(),
                unit: irs_model::radiomap::Unit::GainDb,
                threshold: None,
                feasible: true,
                reason: None,
                path_shape: Default::default(),
                distance_m: Some(0.0),
                travel_time_s: Some(0.0),
                max_feasible_threshold: None,
                start: end.clone(),
                goal: end,
                frame_id: "map".into(),
                waypoints: vec![Waypoint {
                    x: 0.0,
                    y: 0.0,
                    i: 0,
                    j: 0,
                    value: 0.0,
                    yaw_rad: 0.0,
                    distance_m: 0.0,
                    time_s: 0.0,
                    config: CellConfig {
                        ap: 0,
                        phases: vec![vec![theta, 0.5]],
                        power_w: None,
                        decoding_order: None,
                    },
                }],
                vertices: vec![0],
                handovers: Vec::new(),
            };
            let path = format_phases(path, format, precision);
            serde_json::to_value(&path.waypoints[0].config).unwrap()
        };
        assert_eq!(PhasePrecision::default(), PhasePrecision::TenthMilli);
        for (precision, written) in [
            ("1e-2", vec![4.71, 0.5]),
            ("1e-3", vec![4.712, 0.5]),
            ("1e-4", vec![4.7124, 0.5]),
            ("1e-6", vec![4.712389, 0.5]),
            ("full", vec![theta, 0.5]),
        ] {
            let precision: PhasePrecision = precision.parse().unwrap();
            let config = answer(PhaseFormat::Radians, precision);
            assert_eq!(config["irs_phases_rad"], serde_json::json!([written]));
        }
        let codes = answer(PhaseFormat::Codes, PhasePrecision::default());
        assert!(codes["irs_phase_codes"][0].is_string());
        assert_eq!("1e-6".parse::<PhasePrecision>(), Ok(PhasePrecision::Micro));
        assert!("1e-5".parse::<PhasePrecision>().is_err());
    }

    use rand::{RngExt, SeedableRng};

    fn decimals_text(surfaces: Vec<Vec<f64>>, decimals: u32) -> String {
        match SurfacePhases::Radians(surfaces).to_decimals(decimals) {
            SurfacePhases::Decimals(text) => text.get().to_owned(),
            other => panic!("{other:?}"),
        }
    }

    /// Every written phase is the shortest text of the double nearest the decimal it rounds
    /// to (what serde_json writes for that double, where that is not in exponent form), lies in
    /// [0, 2π), is within half a step of θ (modulo 2π), and reads back as written: the Monte
    /// Carlo check evaluates what was sent.
    #[test]
    fn decimals_are_rounded_within_half_a_step_and_shortest() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(14);
        let mut thetas: Vec<f64> = (0..20_000).map(|_| rng.random_range(0.0..TAU)).collect();
        thetas.extend([
            0.0,
            1e-12,
            0.5,
            3.0,
            4.71238898038469,
            TAU - 1e-6,
            TAU - 1e-12,
        ]);
        thetas.extend((0..=628).map(|k| k as f64 / 100.0));
        for decimals in 1..=MAX_PHASE_DECIMALS {
            let text = decimals_text(vec![thetas.clone()], decimals);
            let read: Vec<Vec<f64>> = serde_json::from_str(&text).unwrap();
            let step = 10f64.powi(-(decimals as i32));
            let numbers = text[2..text.len() - 2].split(',');
            for ((&theta, &r), number) in thetas.iter().zip(&read[0]).zip(numbers) {
                assert!((0.0..TAU).contains(&r), "{decimals}: {theta} → {r}");
                let error = (r - theta).abs().min(TAU - (r - theta).abs());
                assert!(
                    error <= step / 2.0 * (1.0 + 1e-6),
                    "{decimals}: {theta} → {r}"
                );
                assert_eq!(number.parse::<f64>().unwrap().to_bits(), r.to_bits());
                if r == 0.0 || r >= 1e-5 {
                    assert_eq!(serde_json::to_string(&r).unwrap(), number, "{theta}");
                }
                assert!(number.len() <= decimals as usize + 2);
            }
        }
        assert_eq!(
            decimals_text(vec![vec![4.71238898038469, TAU - 1e-6, 3.0, 0.0001]], 4),
            "[[4.7124,0.0,3.0,0.0001]]"
        );
        // 12.5 hundredths: a tie, to even.
        assert_eq!(decimals_text(vec![vec![0.125], vec![]], 2), "[[0.12],[]]");
        assert_eq!(decimals_text(vec![], 4), "[]");
    }

    /// Each form reads back as the radians it carries, and serialises under the key its
    /// variant names.
    #[test]
    fn every_form_reads_back_and_serialises_under_its_key() {
        let radians = SurfacePhases::Radians(vec![vec![0.25, 6.0], vec![1.5]]);
        let decimals = radians.to_decimals(2);
        assert_eq!(decimals.radians(), vec![vec![0.25, 6.0], vec![1.5]]);
        assert_eq!(
            serde_json::to_string(&decimals).unwrap(),
            r#"{"irs_phases_rad":[[0.25,6.0],[1.5]]}"#
        );
        assert_eq!(
            serde_json::to_string(&radians).unwrap(),
            serde_json::to_string(&decimals).unwrap()
        );
        assert_eq!(decimals.json_len_hint(), "[[0.25,6.0],[1.5]]".len());
        // Codes from decimals are the codes of the decimals.
        assert_eq!(decimals.to_codes(), radians.to_codes());
        let codes = radians.to_codes();
        for (read, sent) in codes.radians().concat().iter().zip([0.25, 6.0, 1.5]) {
            assert!((read - sent).abs() <= std::f64::consts::PI / 65536.0 + 1e-15);
        }
        assert_eq!(codes.to_decimals(4), codes);
    }
}
