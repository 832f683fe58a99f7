//! What users send, and how it is rejected: the one error type for a bad field, and the parsers
//! that the CLI and the HTTP API share, so a point or a name means the same on both.
//!
//! Every rejection names the offending field by its JSON path (`scenario.ap.position`,
//! `map.phases`, `start`), so a user can fix a request without reading code. An error raised
//! inside a nested document is re-rooted with [`FieldError::within`] by whoever embedded it.

use serde::de::DeserializeOwned;
use serde::de::value::{Error as ValueError, StrDeserializer};
use std::fmt;

/// A rejected input: the JSON path of the offending field and why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {reason}")]
pub struct FieldError {
    /// JSON path of the field (`$` for the document itself).
    pub field: String,
    pub reason: String,
}

impl FieldError {
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
}

/// Parses one of an enum's names as serde spells them, so the CLI, JSON bodies and the docs
/// accept exactly the same words (the error lists them: "unknown variant `x`, expected …").
pub fn parse_name<T: DeserializeOwned>(text: &str) -> Result<T, String> {
    T::deserialize(StrDeserializer::<ValueError>::new(text)).map_err(|e| e.to_string())
}

/// A finite number written as text (query parameters, CLI values).
pub fn parse_finite(text: &str) -> Result<f64, String> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite())
        .ok_or_else(|| format!("{text:?} is not a finite number"))
}

/// A point on the floor written `"x,y"` in metres (`--start`, `?start=`).
pub fn parse_point(text: &str) -> Result<[f64; 2], String> {
    match text.split(',').collect::<Vec<_>>().as_slice() {
        [x, y] => Ok([parse_finite(x)?, parse_finite(y)?]),
        _ => Err(format!("expected \"x,y\" in metres, got {text:?}")),
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
        let whole = FieldError::new("$", "trailing characters");
        assert_eq!(whole.clone().within("scenario.").field, "scenario");
        assert_eq!(whole.within("").field, "$");
    }

    #[test]
    fn points_and_numbers() {
        assert_eq!(parse_point("-10, 0.5"), Ok([-10.0, 0.5]));
        assert!(parse_point("1,2,3").is_err());
        assert!(parse_point("1,NaN").is_err());
        assert!(parse_finite("inf").is_err());
    }
}
