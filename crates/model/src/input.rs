//! What users send, and how it is rejected: the one error type for a bad field, and the parsers
//! that the CLI and the HTTP API share, so a point or a name means the same on both.
//!
//! Every rejection names the offending field by its JSON path (`scenario.ap.position`,
//! `map.phases`, `start`), so a user can fix a request without reading code. An error raised
//! inside a nested document is re-rooted with [`FieldError::within`] by whoever embedded it.

use serde::de::value::{Error as ValueError, StrDeserializer};
use serde::de::{Deserialize, DeserializeOwned, Deserializer};
use std::fmt;

/// A rejected input: the JSON path of the offending field and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct FieldError {
    /// JSON path of the field (`$` for the document itself).
    pub field: String,
    /// Why it was rejected, in words a user can act on.
    pub reason: String,
}

impl FieldError {
    /// An error about `field` (its JSON path) for `reason`.
    pub fn new(field: impl Into<String>, reason: impl fmt::Display) -> Self {
        FieldError {
            field: field.into(),
            reason: reason.to_string(),
        }
    }

    /// The same error seen from an enclosing document whose path to this one is `prefix`
    /// (ending in `.`, e.g. `"map.scenario."`); an error about the whole document (`$`) becomes
    /// an error about the prefix itself.
    pub fn within(self, prefix: &str) -> Self {
        let field = match (self.field.as_str(), prefix.trim_end_matches('.')) {
            (_, "") => self.field,
            ("$", parent) => parent.to_string(),
            (field, _) => format!("{prefix}{field}"),
        };
        FieldError { field, ..self }
    }

    /// The same error with its leading path `from` (the whole path, or followed by `.` or `[`)
    /// written as `to`: `aps[0].position` as `ap.position` for a document that wrote its one
    /// AP on its own.
    pub fn renamed(self, from: &str, to: &str) -> Self {
        let field = match self.field.strip_prefix(from) {
            Some(rest) if rest.is_empty() || rest.starts_with(['.', '[']) => format!("{to}{rest}"),
            _ => self.field,
        };
        FieldError { field, ..self }
    }
}

/// Parses one of an enum's names as serde spells them, so the CLI, JSON bodies and the docs
/// accept exactly the same words (the error lists them: "unknown variant `x`, expected …").
pub fn parse_name<T: DeserializeOwned>(text: &str) -> Result<T, String> {
    T::deserialize(StrDeserializer::<ValueError>::new(text)).map_err(|e| e.to_string())
}

/// For optional fields (`#[serde(default, deserialize_with = "crate::input::present")]`): an
/// absent field is `None`, but an explicit `null` is an error naming the field, so a document
/// has one meaning (`"irs": null` does not quietly mean "no IRS").
pub fn present<'de, D: Deserializer<'de>, T: Deserialize<'de>>(
    d: D,
) -> Result<Option<T>, D::Error> {
    T::deserialize(d).map(Some)
}

/// A JSON scalar that a field takes as a name or as a number (`"max"` or −68, `"none"` or 2),
/// read without committing to one JSON library: [`deserialize_scalar`].
pub(crate) enum Scalar {
    Text(String),
    /// The number, and its text as JSON writes it (`2`, `2.0`, `-68.5`).
    Number(f64, String),
    /// Anything else, as an error message shows it (`true`, `null`, `an array`).
    Other(String),
}

/// Reads a [`Scalar`] from any self-describing format (JSON, YAML).
pub(crate) fn deserialize_scalar<'de, D: Deserializer<'de>>(d: D) -> Result<Scalar, D::Error> {
    struct Visitor;
    impl<'de> serde::de::Visitor<'de> for Visitor {
        type Value = Scalar;
        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            f.write_str("a name or a number")
        }
        fn visit_str<E>(self, v: &str) -> Result<Scalar, E> {
            Ok(Scalar::Text(v.to_string()))
        }
        fn visit_u64<E>(self, v: u64) -> Result<Scalar, E> {
            Ok(Scalar::Number(v as f64, v.to_string()))
        }
        fn visit_i64<E>(self, v: i64) -> Result<Scalar, E> {
            Ok(Scalar::Number(v as f64, v.to_string()))
        }
        fn visit_f64<E>(self, v: f64) -> Result<Scalar, E> {
            // Debug writes the shortest round-trip decimal with a point ("2.0"), as JSON does.
            Ok(Scalar::Number(v, format!("{v:?}")))
        }
        fn visit_bool<E>(self, v: bool) -> Result<Scalar, E> {
            Ok(Scalar::Other(v.to_string()))
        }
        fn visit_unit<E>(self) -> Result<Scalar, E> {
            Ok(Scalar::Other("null".into()))
        }
        fn visit_none<E>(self) -> Result<Scalar, E> {
            Ok(Scalar::Other("null".into()))
        }
        fn visit_seq<A: serde::de::SeqAccess<'de>>(self, _: A) -> Result<Scalar, A::Error> {
            Ok(Scalar::Other("an array".into()))
        }
        fn visit_map<A: serde::de::MapAccess<'de>>(self, _: A) -> Result<Scalar, A::Error> {
            Ok(Scalar::Other("an object".into()))
        }
    }
    d.deserialize_any(Visitor)
}

/// The grammar of a number written as text (query parameters, CLI values), as the OpenAPI
/// contract states it: an optional sign, at most 30 integer digits, an optional fraction and
/// an optional exponent of at most two digits. Every such number is finite (< 1e130), so the
/// grammar alone decides validity and the contract can say exactly what the server accepts.
pub const NUMBER_PATTERN: &str = r"[+-]?([0-9]{1,30}(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]{1,2})?";

/// True when `text` matches [`NUMBER_PATTERN`] exactly.
fn is_number(text: &str) -> bool {
    let b = text.as_bytes();
    let mut k = usize::from(matches!(b.first(), Some(b'+' | b'-')));
    let digits = |k: &mut usize| {
        let start = *k;
        while *k < b.len() && b[*k].is_ascii_digit() {
            *k += 1;
        }
        *k - start
    };
    let integer = digits(&mut k);
    let fraction = if b.get(k) == Some(&b'.') {
        k += 1;
        Some(digits(&mut k))
    } else {
        None
    };
    let mantissa_ok = match (integer, fraction) {
        (1..=30, _) => true,
        (0, Some(f)) => f > 0,
        _ => false,
    };
    if matches!(b.get(k), Some(b'e' | b'E')) {
        k += 1;
        k += usize::from(matches!(b.get(k), Some(b'+' | b'-')));
        if !(1..=2).contains(&digits(&mut k)) {
            return false;
        }
    }
    mantissa_ok && k == b.len()
}

/// A finite number written as text, following [`NUMBER_PATTERN`].
pub fn parse_finite(text: &str) -> Result<f64, String> {
    is_number(text)
        .then(|| text.parse::<f64>().ok())
        .flatten()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("{text:?} is not a decimal number (like -63, 0.5 or 1e-3)"))
}

/// A point on the floor written `"x,y"` in metres (`--start`, `?start=`), two numbers of
/// [`NUMBER_PATTERN`] joined by a comma.
pub fn parse_point(text: &str) -> Result<[f64; 2], String> {
    match text.split(',').collect::<Vec<_>>().as_slice() {
        [x, y] => Ok([parse_finite(x)?, parse_finite(y)?]),
        _ => Err(format!("expected \"x,y\" in metres, got {text:?}")),
    }
}

/// Parses `"x,y,z"` (a position in metres, or a direction).
pub fn parse_point3(text: &str) -> Result<[f64; 3], String> {
    match text.split(',').collect::<Vec<_>>().as_slice() {
        [x, y, z] => Ok([parse_finite(x)?, parse_finite(y)?, parse_finite(z)?]),
        _ => Err(format!("expected \"x,y,z\", got {text:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn within_reroots_paths() {
        let e = FieldError::new("ap.position", "lies inside an obstacle");
        assert_eq!(
            e.clone().within("map.scenario.").field,
            "map.scenario.ap.position"
        );
        assert_eq!(e.clone().within("").field, "ap.position");
        let model = |f: &str| FieldError::new(f, "x");
        assert_eq!(
            model("aps[0].position").renamed("aps[0]", "ap").field,
            "ap.position"
        );
        assert_eq!(model("aps[0]").renamed("aps[0]", "ap").field, "ap");
        assert_eq!(
            model("aps[01].x").renamed("aps[0]", "ap").field,
            "aps[01].x"
        );
        assert_eq!(model("aps[1].x").renamed("aps[0]", "ap").field, "aps[1].x");
        assert_eq!(
            model("irss[0].x").renamed("aps[0]", "ap").field,
            "irss[0].x"
        );
        let whole = FieldError::new("$", "trailing characters");
        assert_eq!(whole.clone().within("scenario.").field, "scenario");
        assert_eq!(whole.within("").field, "$");
    }

    #[test]
    fn points_and_numbers() {
        assert_eq!(parse_point("-10,0.5"), Ok([-10.0, 0.5]));
        assert!(parse_point("1,2,3").is_err());
        assert!(parse_point("1,NaN").is_err());
        assert!(
            parse_point("-10, 0.5").is_err(),
            "no spaces: the contract's pattern has none"
        );
        for ok in [
            "0",
            "-63",
            "+1.5",
            ".5",
            "5.",
            "1e-3",
            "2E+10",
            "123456789012345678901234567890",
        ] {
            assert!(parse_finite(ok).is_ok(), "{ok}");
        }
        for bad in [
            "",
            "-",
            ".",
            "e5",
            "1e",
            "1e100",
            "1e-100",
            "inf",
            "NaN",
            "0x10",
            "1_0",
            " 1",
            "1234567890123456789012345678901",
        ] {
            assert!(parse_finite(bad).is_err(), "{bad}");
        }
    }

    /// The hand-written scanner and the contract's pattern accept the same strings.
    #[test]
    fn scanner_agrees_with_the_pattern() {
        let pattern = format!("^{NUMBER_PATTERN}$");
        let alphabet = ['1', '0', '.', 'e', '-', '+', 'E'];
        let mut checked = 0;
        for len in 1..=5 {
            let mut word = vec![0usize; len];
            loop {
                let text: String = word.iter().map(|&k| alphabet[k]).collect();
                assert_eq!(
                    is_number(&text),
                    regex_lite_match(&pattern, &text),
                    "{text:?}"
                );
                checked += 1;
                let mut k = 0;
                while k < len && word[k] == alphabet.len() - 1 {
                    word[k] = 0;
                    k += 1;
                }
                if k == len {
                    break;
                }
                word[k] += 1;
            }
        }
        assert!(checked > 19_000);
    }

    fn regex_lite_match(pattern: &str, text: &str) -> bool {
        regex_lite::Regex::new(pattern).unwrap().is_match(text)
    }
}
