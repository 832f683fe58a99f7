//! How a waypoint's IRS phases are carried and written: as radians, as radians already written
//! as JSON decimals at a chosen precision, or as 16-bit codes in base64.
//!
//! A path answer is mostly phases (the paper map's path: 2 460 of them), so how they are written
//! decides most of its size and of the server's time on it. Writing decimals goes straight
//! from each phase to its digits in one pass: θ is rounded once to an integer number of steps
//! of 10⁻ᵈ rad and that integer's digits are the text. Going through a rounded f64 and a
//! general float formatter, number by number, was a quarter of the server's CPU on path queries
//! (perf, paper map, 16 connections, every query new). The text is written straight into the
//! answer's body as it is written ([`crate::path_json`]): written ahead of time, each
//! waypoint's text was an allocation kept until the body was written, and those allocations
//! cost more than writing the digits; written through serde, it took a string of its own and
//! a second copy.

use base64::Engine;
use base64::engine::general_purpose::STANDARD as BASE64;
use serde::{Deserialize, Serialize};
use std::f64::consts::TAU;
use std::mem::MaybeUninit;
use std::str::FromStr;

use irs_model::radiomap::SurfaceRadians;
use irs_model::vecmath::ROUNDING_SHIFT;

/// The phase vector θ of one configuration, one vector per IRS in scenario order (N_s values
/// each; none for phases `none`), in radians or as the compact codes a path answer may be
/// asked for ([`PhaseFormat`]); written as a waypoint's field by [`SurfacePhases::write_field`].
#[derive(Debug, Clone)]
pub enum SurfacePhases {
    /// θ in [0, 2π), written as `irs_phases_rad`.
    Radians(SurfaceRadians),
    /// The same JSON array of arrays as `Radians` (`irs_phases_rad`), each phase rounded to d
    /// decimals and written as that decimal ([`SurfacePhases::into_decimals`]).
    Decimals(RoundedPhases),
    /// Each surface's phases as 16-bit codes c, θ = 2π·c/2¹⁶ ([`irs_model::phases::encode_phase`],
    /// within π/2¹⁶ of the phase), little-endian, two bytes a phase, in base64 (RFC 4648 with
    /// padding), written as `irs_phase_codes`: 2.7 characters a phase against 6–7 for a decimal
    /// at 10⁻⁴ rad.
    Codes(Vec<String>),
}

/// Equal when they are written the same way with the same values (decimals: the same
/// rounded values).
impl PartialEq for SurfacePhases {
    fn eq(&self, other: &Self) -> bool {
        match (self, other) {
            (SurfacePhases::Radians(a), SurfacePhases::Radians(b)) => a == b,
            (SurfacePhases::Decimals(a), SurfacePhases::Decimals(b)) => {
                a.decimals == b.decimals && a.radians() == b.radians()
            }
            (SurfacePhases::Codes(a), SurfacePhases::Codes(b)) => a == b,
            _ => false,
        }
    }
}

/// Phases in radians to be written as decimals with at most `decimals` places: each θ ∈ [0, 2π)
/// rounded to the nearest multiple of 10^−`decimals` (ties to even; error ≤ ½·10^−`decimals`
/// rad) and written as that decimal without trailing zeros ("4.7124", "3.5", "0.0"): the
/// shortest text that reads back to the nearest double, what serde_json writes for that double
/// too (except below 10⁻⁵, which it writes in exponent form and this in plain decimals). A
/// phase rounding up to 2π is written as 0, staying in [0, 2π).
#[derive(Debug, Clone)]
pub struct RoundedPhases {
    /// Each surface's phases as computed, rounded only as they are written.
    radians: SurfaceRadians,
    /// 1 to [`MAX_PHASE_DECIMALS`].
    decimals: u32,
}

impl RoundedPhases {
    /// Every surface's phases as written: the doubles their decimals read back as.
    pub fn radians(&self) -> SurfaceRadians {
        let scale = 10f64.powi(self.decimals as i32);
        let wrap = wrap(scale);
        self.radians
            .iter()
            .map(|surface| {
                // k/10ᵈ correctly rounded: the double nearest the decimal, which is what
                // reading the decimal gives.
                surface
                    .iter()
                    .map(|&theta| steps(theta, scale, wrap) as f64 / scale)
                    .collect()
            })
            .collect()
    }

    /// Appends the JSON text, an array of arrays of decimals, to `out`.
    fn write_json(&self, out: &mut Vec<u8>) {
        let write: fn(&[f64], &mut [MaybeUninit<u8>]) -> usize = match self.decimals {
            1 => write_surface::<1>,
            2 => write_surface::<2>,
            3 => write_surface::<3>,
            4 => write_surface::<4>,
            5 => write_surface::<5>,
            6 => write_surface::<6>,
            7 => write_surface::<7>,
            8 => write_surface::<8>,
            9 => write_surface::<9>,
            _ => unreachable!("decimals checked by into_decimals"),
        };
        // Written in place, in room reserved at the longest, so that nothing is zeroed first
        // and nothing copied after.
        out.reserve(self.max_len());
        let start = out.len();
        let room = out.spare_capacity_mut();
        room[0].write(b'[');
        let mut at = 1;
        for (s, surface) in self.radians.iter().enumerate() {
            if s > 0 {
                room[at].write(b',');
                at += 1;
            }
            at += write(surface, &mut room[at..]);
        }
        room[at].write(b']');
        // SAFETY: the first at + 1 bytes of the spare room were written above (a surface's
        // writer writes every byte below the length it returns).
        unsafe { out.set_len(start + at + 1) };
        debug_assert!(
            serde_json::from_slice::<Vec<Vec<f64>>>(&out[start..]).is_ok(),
            "{}",
            String::from_utf8_lossy(&out[start..])
        );
    }

    /// Room for the text: each surface's room ([`surface_len`]) and a comma, the outer
    /// brackets.
    fn max_len(&self) -> usize {
        let surfaces = self.radians.iter();
        2 + surfaces
            .map(|s| surface_len(self.decimals, s.len()) + 1)
            .sum::<usize>()
    }
}

/// Most decimals [`RoundedPhases`] writes: 10⁻⁹ rad is far below any phase
/// shifter's resolution, and keeps k = θ·10⁹ < 2π·10⁹ an exact integer in a double.
pub const MAX_PHASE_DECIMALS: u32 = 9;

impl SurfacePhases {
    /// Appends the phases as a waypoint's field to `out`: `"irs_phases_rad":` and an array of
    /// arrays of numbers (radians, or decimals), or `"irs_phase_codes":` and an array of
    /// strings.
    pub fn write_field(&self, out: &mut Vec<u8>) {
        match self {
            SurfacePhases::Radians(surfaces) => {
                out.extend_from_slice(br#""irs_phases_rad":"#);
                serde_json::to_writer(out, surfaces.as_slice()).expect("numbers serialise");
            }
            SurfacePhases::Decimals(rounded) => {
                out.extend_from_slice(br#""irs_phases_rad":"#);
                rounded.write_json(out);
            }
            SurfacePhases::Codes(surfaces) => {
                out.extend_from_slice(br#""irs_phase_codes":"#);
                serde_json::to_writer(out, surfaces).expect("strings serialise");
            }
        }
    }

    /// The same phases as codes (exact for phases already on the 2π/2¹⁶ grid: rate maps, `bits`).
    pub fn to_codes(&self) -> SurfacePhases {
        let surfaces = match self {
            SurfacePhases::Codes(_) => return self.clone(),
            SurfacePhases::Decimals(rounded) => &rounded.radians(),
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

    /// Radians to be written as decimals with at most `decimals` places ([`RoundedPhases`]).
    /// Other forms are returned as they are.
    ///
    /// # Panics
    /// If `decimals` is 0 or above [`MAX_PHASE_DECIMALS`] (a caller's constant, not input).
    pub fn into_decimals(self, decimals: u32) -> SurfacePhases {
        assert!(
            (1..=MAX_PHASE_DECIMALS).contains(&decimals),
            "phase decimals must lie in 1..={MAX_PHASE_DECIMALS}, got {decimals}"
        );
        match self {
            SurfacePhases::Radians(radians) => {
                SurfacePhases::Decimals(RoundedPhases { radians, decimals })
            }
            other => other,
        }
    }

    /// Every surface's phases in radians (decimals read back, codes decoded).
    pub fn radians(&self) -> SurfaceRadians {
        match self {
            SurfacePhases::Radians(surfaces) => surfaces.clone(),
            SurfacePhases::Decimals(rounded) => rounded.radians(),
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
            SurfacePhases::Decimals(rounded) => rounded.max_len(),
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
/// [`RoundedPhases`], straight from θ to digits.
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

/// The first step count of 10^−d rad whose decimal is ≥ 2π (6.29 at two decimals, 6.2832 at
/// four), for `scale` = 10ᵈ.
fn wrap(scale: f64) -> u64 {
    (TAU * scale).ceil() as u64
}

/// θ ∈ [0, 2π) in steps of 1/`scale` rad, to the nearest (ties to even); below `wrap`, a
/// count reaching it (2π) wrapping to 0.
#[inline(always)]
fn steps(theta: f64, scale: f64, wrap: u64) -> u64 {
    debug_assert!((0.0..TAU).contains(&theta), "phase {theta} outside [0, 2π)");
    // θ·scale + 1.5·2⁵² (θ·scale < 2⁵¹) is rounded to an integer, to nearest, and that integer
    // sits in the low bits of its mantissa: read there, without a conversion to an integer
    // (and the checks of range and NaN that Rust's conversion adds).
    let steps = (theta * scale + ROUNDING_SHIFT)
        .to_bits()
        .wrapping_sub(ROUNDING_SHIFT.to_bits());
    if steps >= wrap { 0 } else { steps }
}

/// Every group of four decimals, "0000" to "9999", as a fraction ending in it is written: the
/// digits kept once trailing zeros are dropped, at least one ("1230" → "123", "0000" → "0"),
/// and a comma, in bytes 0 to 4; the number of digits kept without that minimum (0 for "0000",
/// 3 for "1230") in byte 5; the length of "d.", the digits kept and the comma in byte 7. A
/// phase's fraction is one lookup a group, no loop for its zeros: with one group, the lookup
/// and the whole digit make one 8-byte store. 80 kB, built at compile time. (A table of pairs
/// would stay in the first-level cache, but its extra arithmetic made a phase 2.6 times
/// slower.)
static FOUR_DIGITS: [[u8; 8]; 10_000] = four_digits();

const fn four_digits() -> [[u8; 8]; 10_000] {
    let mut table = [[0u8; 8]; 10_000];
    let mut n = 0;
    while n < 10_000 {
        let digits = [n / 1000, n / 100 % 10, n / 10 % 10, n % 10];
        let mut k = 0;
        while k < 4 {
            table[n][k] = b'0' + digits[k] as u8;
            if digits[k] != 0 {
                table[n][5] = k as u8 + 1;
            }
            k += 1;
        }
        let shown = if table[n][5] == 0 { 1 } else { table[n][5] };
        table[n][shown as usize] = b',';
        table[n][7] = 2 + shown + 1;
        n += 1;
    }
    table
}

/// One surface's phases as a JSON array of decimals with at most `D` places (see
/// [`RoundedPhases`]) at the start of `out`, which has room for them ([`surface_len`]);
/// returns the length of the text, every byte of which is written. `D` is a constant so that
/// the powers of ten are too, the divisions below become multiplications and the loops over
/// groups unroll.
fn write_surface<const D: u32>(phases: &[f64], out: &mut [MaybeUninit<u8>]) -> usize {
    let scale = 10u64.pow(D);
    // The fraction as whole groups of four digits, padded on the right: D = 6 writes
    // "dddddd00", whose padding is trailing zeros and so never kept.
    const MAX_GROUPS: usize = MAX_PHASE_DECIMALS.div_ceil(4) as usize;
    let groups = D.div_ceil(4) as usize;
    let pad = 10u64.pow(4 * groups as u32 - D);
    let wrap = wrap(scale as f64);
    // Each number is written whole, with its comma: "d." and its first group in one 8-byte
    // store, the other groups after it; the next byte written overwrites what it does not
    // keep. The k-th of n numbers starts at most 1 + k·(4·groups + 3) bytes in, so every byte
    // written lies within `surface_len`. The writes below are unchecked on the strength of it:
    // bounds checks were a quarter of the time a phase.
    assert!(out.len() >= surface_len(D, phases.len()));
    let out = out.as_mut_ptr().cast::<u8>();
    // SAFETY (every write below): at the offsets bounded above.
    unsafe { *out = b'[' };
    let mut at = 1;
    for &theta in phases {
        let steps = steps(theta, scale as f64, wrap);
        // The whole part is a single digit, as steps < wrap ≤ 6.3·10ᴰ.
        let whole = steps / scale;
        let mut fraction = (steps - whole * scale) * pad;
        let mut index = [0; MAX_GROUPS];
        for g in (1..groups).rev() {
            index[g] = (fraction % 10_000) as usize;
            fraction /= 10_000;
        }
        index[0] = fraction as usize;
        let first = u64::from_le_bytes(FOUR_DIGITS[index[0]]);
        let whole = (b'0' as u64 + whole) | (b'.' as u64) << 8;
        if groups == 1 {
            // "d.", the digits kept and the comma in one store; its spare bytes are
            // overwritten by whatever follows the number.
            let word = whole | (first & 0xff_ffff_ffff) << 16;
            unsafe { std::ptr::write_unaligned(out.add(at).cast::<u64>(), word.to_le()) };
            at += (first >> 56) as usize;
            continue;
        }
        // Several groups: each written with all four digits, the comma after the digits kept,
        // which run to the last one other than 0 (the rightmost group with one decides), at
        // least one ("3.0").
        let word = whole | all_four(first) << 16;
        unsafe { std::ptr::write_unaligned(out.add(at).cast::<u64>(), word.to_le()) };
        let mut digits_kept = (kept(first) as usize).max(1);
        for (g, &index) in index.iter().enumerate().take(groups).skip(1) {
            let group = u64::from_le_bytes(FOUR_DIGITS[index]);
            let digits = (all_four(group) as u32).to_le_bytes();
            unsafe { std::ptr::copy_nonoverlapping(digits.as_ptr(), out.add(at + 2 + 4 * g), 4) };
            if kept(group) != 0 {
                digits_kept = 4 * g + kept(group) as usize;
            }
        }
        at += 2 + digits_kept;
        unsafe { *out.add(at) = b',' };
        at += 1;
    }
    // The last number's comma is overwritten by the bracket.
    let end = if phases.is_empty() { at } else { at - 1 };
    unsafe { *out.add(end) = b']' };
    end + 1
}

/// A [`FOUR_DIGITS`] entry's digits kept, without the minimum of one.
fn kept(entry: u64) -> u32 {
    (entry >> 40) as u8 as u32
}

/// A [`FOUR_DIGITS`] entry's four digits, trailing zeros and all ("123," → "1230"), in the low
/// four bytes: the zeros it drops put back where it kept none.
fn all_four(entry: u64) -> u64 {
    let kept = (1u64 << (8 * kept(entry))) - 1;
    (entry & kept) | (0x3030_3030 & !kept)
}

/// The room [`write_surface`] needs for `phases` phases at `decimals` places: two brackets;
/// "d.", the digits (whole groups of four) and a comma a phase; the two bytes the last
/// number's first store can reach past its digits.
const fn surface_len(decimals: u32, phases: usize) -> usize {
    2 + phases * (4 * decimals.div_ceil(4) as usize + 3) + 2
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
                        phases: vec![vec![theta, 0.5]].into(),
                        power_w: None,
                        decoding_order: None,
                    },
                }],
                vertices: vec![0],
                handovers: Vec::new(),
            };
            let path = format_phases(path, format, precision);
            field(&path.waypoints[0].config.phases)
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

    /// The phases as their field, in an object of their own.
    fn field(phases: &SurfacePhases) -> serde_json::Value {
        let mut text = b"{".to_vec();
        phases.write_field(&mut text);
        text.push(b'}');
        serde_json::from_slice(&text).unwrap()
    }

    fn decimals_text(surfaces: Vec<Vec<f64>>, decimals: u32) -> String {
        match SurfacePhases::Radians(surfaces.into()).into_decimals(decimals) {
            SurfacePhases::Decimals(rounded) => {
                // Written after other text, as in a body.
                let mut written = b"ab".to_vec();
                rounded.write_json(&mut written);
                let text = String::from_utf8(written.split_off(2)).unwrap();
                // What the answer says it sent is what the text reads back as, bit for bit.
                let read: Vec<Vec<f64>> = serde_json::from_str(&text).unwrap();
                let bits = |v: Vec<Vec<f64>>| -> Vec<u64> {
                    v.concat().into_iter().map(f64::to_bits).collect()
                };
                assert_eq!(bits(read), bits(rounded.radians().into_vec()), "{text}");
                text
            }
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

    /// Every step count k (θ = k·10⁻ᵈ) is written as its decimal: k's whole part, a point and
    /// the d digits of its fraction with the trailing zeros dropped but one. Every count at one
    /// to four decimals; at more, the counts ending in every run of zeros and 50 000 drawn.
    #[test]
    fn every_step_count_is_written_as_its_decimal() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(35);
        for decimals in 1..=MAX_PHASE_DECIMALS {
            let scale = 10u64.pow(decimals);
            let wrap = (TAU * scale as f64).ceil() as u64;
            let counts: Vec<u64> = if decimals <= 4 {
                (0..wrap).collect()
            } else {
                let ends = (0..=decimals).flat_map(|zeros| {
                    let step = 10u64.pow(zeros);
                    [
                        step,
                        7 * step,
                        1234 * step,
                        scale + step,
                        wrap / step * step,
                    ]
                });
                let drawn = (0..50_000).map(|_| rng.random_range(0..wrap));
                ends.filter(|&k| k < wrap).chain(drawn).collect()
            };
            let thetas = counts.iter().map(|&k| k as f64 / scale as f64).collect();
            let text = decimals_text(vec![thetas], decimals);
            let numbers: Vec<&str> = text[2..text.len() - 2].split(',').collect();
            assert_eq!(numbers.len(), counts.len());
            for (&k, number) in counts.iter().zip(numbers) {
                let digits = format!("{:0width$}", k % scale, width = decimals as usize);
                let fraction = match digits.trim_end_matches('0') {
                    "" => "0",
                    kept => kept,
                };
                assert_eq!(
                    number,
                    format!("{}.{fraction}", k / scale),
                    "{decimals}: {k}"
                );
            }
        }
    }

    /// Each form reads back as the radians it carries, and is written under the key its
    /// variant names.
    #[test]
    fn every_form_reads_back_and_is_written_under_its_key() {
        let text = |phases: &SurfacePhases| {
            let mut text = Vec::new();
            phases.write_field(&mut text);
            String::from_utf8(text).unwrap()
        };
        let radians = SurfacePhases::Radians(vec![vec![0.25, 6.0], vec![1.5]].into());
        let decimals = radians.clone().into_decimals(2);
        assert_eq!(
            decimals.radians().into_vec(),
            vec![vec![0.25, 6.0], vec![1.5]]
        );
        assert_eq!(text(&decimals), r#""irs_phases_rad":[[0.25,6.0],[1.5]]"#);
        assert_eq!(text(&radians), text(&decimals));
        assert_eq!(
            text(&SurfacePhases::Codes(vec!["AAA=".into()])),
            r#""irs_phase_codes":["AAA="]"#
        );
        // Decimals' hint is an upper bound, so that a buffer sized by it is never regrown.
        let hint = decimals.json_len_hint();
        assert!((18..=2 * 18).contains(&hint), "{hint}");
        // Codes from decimals are the codes of the decimals.
        assert_eq!(decimals.to_codes(), radians.to_codes());
        let codes = radians.to_codes();
        for (read, sent) in codes.radians().concat().iter().zip([0.25, 6.0, 1.5]) {
            assert!((read - sent).abs() <= std::f64::consts::PI / 65536.0 + 1e-15);
        }
        assert_eq!(codes.clone().into_decimals(4), codes);
    }
}
