//! JSON documents with every object's keys unique. serde_json keeps the last of a repeated key
//! when it builds a `Value` or a map (a derived struct refuses a repeated field, but not one
//! inside a map or a `Value`), so `{"x": 1, "x": 2}` would silently mean `{"x": 2}`, and two
//! readers of one document could disagree on what it says. Every front door (scenario files and
//! documents, HTTP request bodies) checks its text with [`check_unique_keys`].

use irs_model::input::FieldError;
use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use std::borrow::Cow;
use std::cell::RefCell;
use std::collections::HashSet;
use std::fmt;

/// Where a value sits in the document, built as the walk goes down (no allocation per value);
/// written as serde_path_to_error writes paths (`floor_plan.origin[2]`), `$` for the root.
#[derive(Clone, Copy)]
enum Path<'a> {
    Root,
    Key(&'a Path<'a>, &'a str),
    Index(&'a Path<'a>, usize),
}

impl fmt::Display for Path<'_> {
    fn fmt(&self, f: &mut fmt::Formatter) -> fmt::Result {
        match self {
            Path::Root => f.write_str("$"),
            Path::Key(Path::Root, key) => f.write_str(key),
            Path::Key(parent, key) => write!(f, "{parent}.{key}"),
            Path::Index(parent, k) => write!(f, "{parent}[{k}]"),
        }
    }
}

/// Deserialises `value` as `T`, an error naming the JSON path of the field it is about. A
/// missing field is named itself (`mru.v_max_mps`), where serde's error sits on the object that
/// lacks it; paths are written as [`check_unique_keys`] writes them.
pub fn from_value_at_path<T: de::DeserializeOwned>(
    value: serde_json::Value,
) -> Result<T, FieldError> {
    serde_path_to_error::deserialize(value).map_err(|e| {
        let path = match e.path().to_string() {
            p if p == "." || p.is_empty() => None,
            p => Some(p),
        };
        let reason = e.into_inner().to_string();
        match (missing_field(&reason), path) {
            (Some(name), Some(parent)) => {
                FieldError::new(format!("{parent}.{name}"), "required, but missing")
            }
            (Some(name), None) => FieldError::new(name, "required, but missing"),
            (None, path) => FieldError::new(path.unwrap_or_else(|| "$".into()), reason),
        }
    })
}

/// The field serde's message ``missing field `name` `` names (its wording since serde 1.0).
fn missing_field(reason: &str) -> Option<&str> {
    let rest = reason.strip_prefix("missing field `")?;
    rest.find('`').map(|end| &rest[..end])
}

/// Checks that no object in the JSON text `bytes` repeats a key. The error names the object's
/// path (`$` for the top level) and the key: ``duplicate key `x` ``. Text that is not JSON at
/// all is reported at `$`; callers parse it first, so their own syntax errors come first.
pub fn check_unique_keys(bytes: &[u8]) -> Result<(), FieldError> {
    let duplicate = RefCell::new(None);
    let mut reader = serde_json::Deserializer::from_slice(bytes);
    let walked = Walk {
        path: Path::Root,
        duplicate: &duplicate,
    }
    .deserialize(&mut reader)
    .and_then(|()| reader.end());
    match (walked, duplicate.into_inner()) {
        (_, Some(error)) => Err(error),
        (Ok(()), None) => Ok(()),
        (Err(e), None) => Err(FieldError::new("$", format!("not a JSON document: {e}"))),
    }
}

/// One value of the walk: objects check their keys, arrays and objects walk their items,
/// anything else is skipped.
struct Walk<'p, 'c> {
    path: Path<'p>,
    duplicate: &'c RefCell<Option<FieldError>>,
}

impl<'de> DeserializeSeed<'de> for Walk<'_, '_> {
    type Value = ();
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<(), D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Walk<'_, '_> {
    type Value = ();

    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("any JSON value")
    }
    fn visit_bool<E>(self, _: bool) -> Result<(), E> {
        Ok(())
    }
    fn visit_i64<E>(self, _: i64) -> Result<(), E> {
        Ok(())
    }
    fn visit_u64<E>(self, _: u64) -> Result<(), E> {
        Ok(())
    }
    fn visit_f64<E>(self, _: f64) -> Result<(), E> {
        Ok(())
    }
    fn visit_str<E>(self, _: &str) -> Result<(), E> {
        Ok(())
    }
    fn visit_unit<E>(self) -> Result<(), E> {
        Ok(())
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut items: A) -> Result<(), A::Error> {
        let mut k = 0;
        while items
            .next_element_seed(Walk {
                path: Path::Index(&self.path, k),
                duplicate: self.duplicate,
            })?
            .is_some()
        {
            k += 1;
        }
        Ok(())
    }

    fn visit_map<A: MapAccess<'de>>(self, mut entries: A) -> Result<(), A::Error> {
        // A set, not a list: an object of 100 000 keys must not cost 10¹⁰ comparisons.
        let mut seen: HashSet<Cow<'de, str>> = HashSet::new();
        while let Some(key) = entries.next_key_seed(Key)? {
            if seen.contains(&key) {
                *self.duplicate.borrow_mut() = Some(FieldError::new(
                    self.path.to_string(),
                    format!("duplicate key `{key}`"),
                ));
                // Stops the walk; the error itself is the one recorded above.
                return Err(de::Error::custom("duplicate key"));
            }
            entries.next_value_seed(Walk {
                path: Path::Key(&self.path, &key),
                duplicate: self.duplicate,
            })?;
            seen.insert(key);
        }
        Ok(())
    }
}

/// An object's key, borrowed from the text when it has no escapes.
struct Key;

impl<'de> DeserializeSeed<'de> for Key {
    type Value = Cow<'de, str>;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Cow<'de, str>, D::Error> {
        d.deserialize_str(self)
    }
}

impl<'de> Visitor<'de> for Key {
    type Value = Cow<'de, str>;
    fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
        f.write_str("an object key")
    }
    fn visit_borrowed_str<E>(self, v: &'de str) -> Result<Cow<'de, str>, E> {
        Ok(Cow::Borrowed(v))
    }
    fn visit_str<E>(self, v: &str) -> Result<Cow<'de, str>, E> {
        Ok(Cow::Owned(v.to_string()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn duplicate(text: &str) -> Option<(String, String)> {
        check_unique_keys(text.as_bytes())
            .err()
            .map(|e| (e.field, e.reason))
    }

    #[test]
    fn a_repeated_key_is_named_with_its_object_path() {
        assert_eq!(duplicate(r#"{"a": 1, "b": {"c": [1, {"d": 2}]}}"#), None);
        assert_eq!(
            duplicate(r#"{"x": 1, "x": 2}"#),
            Some(("$".into(), "duplicate key `x`".into()))
        );
        assert_eq!(
            duplicate(
                r#"{"floor_plan": {"resolution": 0.05, "origin": [0, 0, 0], "resolution": 1}}"#
            ),
            Some(("floor_plan".into(), "duplicate key `resolution`".into()))
        );
        assert_eq!(
            duplicate(r#"{"waypoints": [{"x": 1}, {"x": 1, "y": 2, "x": 3}]}"#),
            Some(("waypoints[1]".into(), "duplicate key `x`".into()))
        );
        // The same key in two objects, or escaped differently but equal, as JSON compares them.
        assert_eq!(duplicate(r#"[{"x": 1}, {"x": 2}]"#), None);
        assert_eq!(
            duplicate(r#"{"a": {"k": 1, "\u006b": 2}}"#),
            Some(("a".into(), "duplicate key `k`".into()))
        );
    }

    #[test]
    fn what_is_not_json_is_reported_at_the_root() {
        let e = check_unique_keys(b"{\"x\": ").unwrap_err();
        assert_eq!(e.field, "$");
        assert!(e.reason.starts_with("not a JSON document"), "{e}");
        assert!(check_unique_keys(b"{} {}").is_err(), "trailing text");
    }
}
