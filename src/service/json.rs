//! Large JSON answers (paths), written straight into one buffer, with the numbers most of them
//! are made of written cheaply: a path answer is mostly IRS phases rounded to at most four
//! decimals (the default `phase_precision` of 1e-4 rad), and the general shortest-decimal
//! algorithm was a fifth of the server's time on path queries (perf, paper map, 16
//! connections).

use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use serde_json::ser::{CompactFormatter, Formatter};
use std::io;
use std::time::Instant;

use super::errors::ApiError;
use crate::vecmath::ROUNDING_SHIFT;

/// `value` serialised into one buffer of about `capacity` bytes (sized by the caller so it is not
/// regrown and copied on the way to hundreds of kilobytes).
pub(super) fn serialize_sized(
    value: &impl Serialize,
    capacity: usize,
) -> Result<Vec<u8>, ApiError> {
    let mut body = Vec::with_capacity(capacity);
    let mut serializer = serde_json::Serializer::with_formatter(&mut body, FewDecimals);
    value
        .serialize(&mut serializer)
        .map_err(|e| ApiError::internal(e.to_string()))?;
    Ok(body)
}

/// A JSON answer from `open`, an object's text without its closing brace, closed with
/// `took_ms` (the milliseconds since `started`, to the microsecond) as its last field.
pub(super) fn with_took_ms(open: &[u8], started: Instant) -> Response {
    let took_ms = started.elapsed().as_micros() as f64 / 1e3;
    let mut body = Vec::with_capacity(open.len() + 32);
    body.extend_from_slice(open);
    body.extend_from_slice(b",\"took_ms\":");
    let mut serializer = serde_json::Serializer::with_formatter(&mut body, FewDecimals);
    match took_ms.serialize(&mut serializer) {
        Ok(()) => {
            body.push(b'}');
            ([(header::CONTENT_TYPE, "application/json")], body).into_response()
        }
        Err(e) => ApiError::internal(e.to_string()).into_response(),
    }
}

/// Largest magnitude written by [`write_few_decimals`]: far below 2⁵³/10⁴, so k = 10⁴·v is an
/// exact integer, and where doubles are spaced below 10⁻⁷, so the only decimal of at most four
/// places that reads back to v is k/10⁴ itself: that is then the shortest form.
const FEW_DECIMALS_BELOW: f64 = 1e9;

/// serde_json's compact output, except that a double equal to the nearest double to a decimal
/// of at most four places is written from integers (same value, same text up to trailing
/// zeros: "3.62", "3.0").
struct FewDecimals;

impl Formatter for FewDecimals {
    fn write_f64<W: ?Sized + io::Write>(&mut self, writer: &mut W, value: f64) -> io::Result<()> {
        match write_few_decimals(value, &mut [0u8; 32]) {
            Some(text) => writer.write_all(text),
            None => CompactFormatter.write_f64(writer, value),
        }
    }
}

/// `value` as "[-]integer.fraction" with one to four fraction digits, written right to left
/// into the end of `buffer` (one copy into the answer afterwards), or `None` when it is not
/// k/10⁴ for an integer k, or is too large (see [`FEW_DECIMALS_BELOW`]).
fn write_few_decimals(value: f64, buffer: &mut [u8; 32]) -> Option<&[u8]> {
    if value.is_nan() || value.abs() >= FEW_DECIMALS_BELOW {
        return None;
    }
    // Rounded to an integer (a tie k + ½ is never k/10⁴, so ties to even change nothing).
    let magnitude = value.abs() * 1e4;
    let scaled = (magnitude + ROUNDING_SHIFT) - ROUNDING_SHIFT;
    if scaled / 1e4 != value.abs() {
        return None;
    }
    let k = scaled as u64;
    let (mut whole, mut fraction) = (k / 10_000, k % 10_000);
    let mut start = buffer.len();
    let mut push = |byte: u8| {
        start -= 1;
        buffer[start] = byte;
    };
    // The fraction without its trailing zeros, at least one digit ("3.0").
    let mut digits = 4;
    while digits > 1 && fraction % 10 == 0 {
        fraction /= 10;
        digits -= 1;
    }
    for _ in 0..digits {
        push(b'0' + (fraction % 10) as u8);
        fraction /= 10;
    }
    push(b'.');
    loop {
        push(b'0' + (whole % 10) as u8);
        whole /= 10;
        if whole == 0 {
            break;
        }
    }
    if value.is_sign_negative() {
        push(b'-');
    }
    Some(&buffer[start..])
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn written(value: f64) -> String {
        let mut out = Vec::new();
        let mut serializer = serde_json::Serializer::with_formatter(&mut out, FewDecimals);
        value.serialize(&mut serializer).unwrap();
        String::from_utf8(out).unwrap()
    }

    /// Every double reads back exactly; the rounded ones are written as the default formatter
    /// writes them (the shortest decimal), others by the default formatter itself.
    #[test]
    fn numbers_read_back_exactly_and_rounded_ones_shortest() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        for _ in 0..100_000 {
            let theta: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            let decimals = rng.random_range(0..=6);
            let scale = 10f64.powi(decimals);
            let wide: f64 = rng.random_range(-2e9..2e9);
            for v in [
                theta,
                (theta * scale).round() / scale,
                -(theta * scale).round() / scale,
                (wide * scale).round() / scale,
                wide,
            ] {
                let text = written(v);
                assert_eq!(
                    text.parse::<f64>().unwrap().to_bits(),
                    v.to_bits(),
                    "{v}: {text}"
                );
                assert_eq!(text, serde_json::to_string(&v).unwrap(), "{v}");
            }
        }
        for v in [
            0.0,
            -0.0,
            3.0,
            0.0001,
            6.2821,
            -0.5,
            1e9 - 0.0001,
            1e9,
            1e-300,
            1e300,
        ] {
            let text = written(v);
            assert_eq!(
                text.parse::<f64>().unwrap().to_bits(),
                v.to_bits(),
                "{v}: {text}"
            );
        }
        assert_eq!(written(f64::NAN), "null");
    }

    #[test]
    fn the_fast_path_is_taken_for_rounded_phases_only() {
        let mut buffer = [0u8; 32];
        assert_eq!(
            write_few_decimals(4.7124, &mut buffer),
            Some(&b"4.7124"[..])
        );
        assert_eq!(write_few_decimals(3.5, &mut buffer), Some(&b"3.5"[..]));
        assert_eq!(write_few_decimals(-2.0, &mut buffer), Some(&b"-2.0"[..]));
        assert_eq!(
            write_few_decimals(0.0001, &mut buffer),
            Some(&b"0.0001"[..])
        );
        assert_eq!(write_few_decimals(4.71239, &mut buffer), None);
        assert_eq!(write_few_decimals(1e12, &mut buffer), None);
    }
}
