//! The scenario document: a scenario as JSON (docs/scenarios.md), in and out.
//!
//! * In: strict parsing whose every error names the field's JSON path, a floor plan's image
//!   decoded from base64, file references (`floor_plan.map`) resolved where files are, then the
//!   model's validation ([`Scenario::validated`]).
//! * Out: the canonical form (keys sorted, no white space, defaults resolved, −0 written as 0)
//!   and its hash, the scenario id: the same scenario has the same id however it was written.
//! * The built-in scenarios.
//!
//! The wire form itself, where one AP or IRS may be written on its own, is [`Document`]; the
//! JSON entry points are the methods of [`ScenarioDocument`], implemented for the model's
//! [`Scenario`], so a caller writes `Scenario::from_json(text)` with this trait in scope.

mod document;

pub use document::Document;

use crate::{files, json, mapfile};
use base64::Engine;
use irs_model::input::FieldError;
use irs_model::scenario::Scenario;
use sha2::{Digest, Sha256};
use std::io::Write;
use std::path::Path;
use std::sync::Arc;

/// The scenarios compiled into every build (name, document): the paper's two set-ups and a
/// small floor for quick tries. `scenarios/README.md` describes them.
pub const BUILTIN: [(&str, &str); 3] = [
    (
        "paper-single-user",
        include_str!("../../../../scenarios/paper-single-user.json"),
    ),
    (
        "paper-multi-user",
        include_str!("../../../../scenarios/paper-multi-user.json"),
    ),
    (
        "small-test",
        include_str!("../../../../scenarios/small-test.json"),
    ),
];

/// A scenario's JSON document: how a [`Scenario`] is read, written and identified.
pub trait ScenarioDocument: Sized {
    /// A built-in scenario by name (see [`BUILTIN`]).
    fn builtin(name: &str) -> Option<Self>;

    /// A variant of a built-in scenario: `edit` changes its JSON document before it is parsed
    /// and validated (defaults are resolved after the edit). `None` for an unknown name.
    fn builtin_with(
        name: &str,
        edit: impl FnOnce(&mut serde_json::Value),
    ) -> Option<Result<Self, FieldError>>;

    /// Parses and validates a scenario document.
    fn from_json(text: &str) -> Result<Self, FieldError>;

    /// Validates a scenario that arrived already deserialised (e.g. embedded in a request).
    fn from_value(value: serde_json::Value) -> Result<Self, FieldError>;

    /// Reads a scenario file (a regular file of at most [`files::MAX_SCENARIO_FILE_BYTES`]): a
    /// `floor_plan.map` in it names a map YAML relative to the file's folder (see
    /// [`mapfile::resolve_map_reference`]).
    fn from_file(path: &Path) -> Result<Self, FieldError>;

    /// Validates a document whose file references (`floor_plan.map`) are relative to `base`.
    fn from_value_with_files(value: serde_json::Value, base: &Path) -> Result<Self, FieldError>;

    /// The document as a JSON value: defaults resolved, one AP as `ap` and one IRS as `irs`.
    fn to_json_value(&self) -> serde_json::Value;

    /// The canonical form: keys sorted, no white space, defaults resolved, −0 written as 0.
    fn canonical_json(&self) -> String;

    /// The scenario id: the first 128 bits of SHA-256 over the canonical form, in hex.
    fn content_hash(&self) -> String;
}

impl ScenarioDocument for Scenario {
    fn builtin(name: &str) -> Option<Scenario> {
        Scenario::builtin_with(name, |_| {})
            .map(|s| s.expect("built-in scenarios are valid (tested)"))
    }

    fn builtin_with(
        name: &str,
        edit: impl FnOnce(&mut serde_json::Value),
    ) -> Option<Result<Scenario, FieldError>> {
        let (_, text) = BUILTIN.iter().find(|(n, _)| *n == name)?;
        let mut document: serde_json::Value =
            serde_json::from_str(text).expect("built-in scenarios are JSON");
        edit(&mut document);
        Some(Scenario::from_value(document))
    }

    fn from_json(text: &str) -> Result<Scenario, FieldError> {
        Scenario::from_value(document(text)?)
    }

    fn from_value(value: serde_json::Value) -> Result<Scenario, FieldError> {
        mapfile::reject_map_reference(&value)?;
        crate::route_graph::reject_graph_reference(&value)?;
        crate::json::from_value_at_path::<Document>(value)?.validated(&image_file)
    }

    fn from_file(path: &Path) -> Result<Scenario, FieldError> {
        let text = files::read_regular_text(path, files::MAX_SCENARIO_FILE_BYTES)
            .map_err(|e| FieldError::new("$", e))?;
        Scenario::from_value_with_files(document(&text)?, path.parent().unwrap_or(Path::new(".")))
    }

    fn from_value_with_files(
        mut value: serde_json::Value,
        base: &Path,
    ) -> Result<Scenario, FieldError> {
        mapfile::resolve_map_reference(&mut value, base, &files::read_regular)?;
        crate::route_graph::resolve_graph_reference(&mut value, base, &files::read_regular)?;
        Scenario::from_value(value)
    }

    fn to_json_value(&self) -> serde_json::Value {
        serde_json::to_value(Document::from(self)).expect("a scenario always serialises")
    }

    fn canonical_json(&self) -> String {
        let mut out = Vec::new();
        write_canonical(&self.to_json_value(), &mut out).expect("writing into memory");
        String::from_utf8(out).expect("JSON text is UTF-8")
    }

    fn content_hash(&self) -> String {
        content_hashes(&[self]).pop().expect("one id per scenario")
    }
}

/// [`ScenarioDocument::content_hash`] of each scenario, hashing a floor plan's image once for
/// the scenarios that share it (the same `Arc`) and the canonical text before it: a placement
/// search names every candidate, each carrying the base's image, megabytes of base64 that
/// cost a millisecond a hash (a quarter of the warehouse's placement search when each
/// candidate hashed its own).
///
/// The canonical text is written with the image left empty, and the hash taken over the text
/// before the image, the image (base64 has no character JSON escapes, so the canonical form
/// writes it as it is) and the text after it. The state after the image is reused while the
/// text before it is unchanged.
pub fn content_hashes(scenarios: &[&Scenario]) -> Vec<String> {
    // The text before the image, the image, and the hash's state after both.
    let mut shared: Option<(Vec<u8>, Arc<str>, Sha256)> = None;
    scenarios
        .iter()
        .map(|scenario| {
            let whole = || hex(&Sha256::digest(scenario.canonical_json().as_bytes()));
            let Some(image) = scenario.floor_plan.as_ref().map(|plan| plan.image.clone()) else {
                return whole();
            };
            let mut blank = (*scenario).clone();
            if let Some(plan) = &mut blank.floor_plan {
                plan.image = Arc::from("");
            }
            let text = blank.canonical_json().into_bytes();
            let at = image_position(&text);
            let (before, after) = text.split_at(at);
            let reusable = shared.as_ref().is_some_and(|(prefix, shared_image, _)| {
                prefix.as_slice() == before && Arc::ptr_eq(shared_image, &image)
            });
            if !reusable {
                // A document's image is base64 (decoded when read); one made otherwise, with
                // text JSON escapes, is hashed as written.
                if needs_escapes(&image) {
                    return whole();
                }
                let mut state = Sha256::new();
                state.update(before);
                state.update(image.as_bytes());
                shared = Some((before.to_vec(), image, state));
            }
            let (_, _, state) = shared.as_ref().expect("set above");
            let mut state = state.clone();
            state.update(after);
            hex(&state.finalize())
        })
        .collect()
}

/// Where the image's text goes in the canonical text of a scenario whose floor plan has an
/// empty image: just inside the quotes of `floor_plan.image` (a key's quotes are never part of
/// a string value's text, where JSON escapes them).
fn image_position(text: &[u8]) -> usize {
    let find = |needle: &[u8], from: usize| {
        text[from..]
            .windows(needle.len())
            .position(|w| w == needle)
            .map(|k| from + k + needle.len())
            .expect("a floor plan's canonical text has its image")
    };
    let plan = find(br#""floor_plan":{"#, 0);
    find(br#""image":""#, plan)
}

/// A floor plan's image file from the base64 text of `floor_plan.image`.
fn image_file(text: &str) -> Result<Vec<u8>, String> {
    base64::engine::general_purpose::STANDARD
        .decode(text.as_bytes())
        .map_err(|e| format!("not valid base64: {e}"))
}

/// A scenario's text as a JSON value (before any field is looked at), for callers that edit the
/// document first (the CLI's `--floor-plan`). A key repeated in an object is refused (see
/// [`json`]): the value would otherwise be the last one, silently.
pub fn document(text: &str) -> Result<serde_json::Value, FieldError> {
    let value = serde_json::from_str(text)
        .map_err(|e| FieldError::new("$", format!("not a JSON document: {e}")))?;
    json::check_unique_keys(text.as_bytes())?;
    Ok(value)
}

/// First 128 bits of SHA-256 of `bytes`, as 32 lowercase hex digits.
pub fn hash_hex(bytes: &[u8]) -> String {
    hex(&Sha256::digest(bytes))
}

/// True when JSON escapes some of `text`'s characters. The scan is branch-free within a chunk
/// so that it vectorises: a floor plan's image is megabytes of base64, scanned per id.
fn needs_escapes(text: &str) -> bool {
    text.as_bytes().chunks(256).any(|chunk| {
        chunk.iter().fold(false, |found, &b| {
            found | (b < 0x20) | (b == b'"') | (b == b'\\')
        })
    })
}

/// The first 128 bits of a digest in hex.
fn hex(digest: &[u8]) -> String {
    digest[..16].iter().map(|b| format!("{b:02x}")).collect()
}

fn write_canonical(value: &serde_json::Value, out: &mut impl Write) -> std::io::Result<()> {
    use serde_json::Value;
    match value {
        Value::Object(map) => {
            let mut keys: Vec<&String> = map.keys().collect();
            keys.sort();
            out.write_all(b"{")?;
            for (k, key) in keys.into_iter().enumerate() {
                if k > 0 {
                    out.write_all(b",")?;
                }
                serde_json::to_writer(&mut *out, key)?;
                out.write_all(b":")?;
                write_canonical(&map[key], out)?;
            }
            out.write_all(b"}")
        }
        Value::Array(items) => {
            out.write_all(b"[")?;
            for (k, item) in items.iter().enumerate() {
                if k > 0 {
                    out.write_all(b",")?;
                }
                write_canonical(item, out)?;
            }
            out.write_all(b"]")
        }
        Value::Number(n) => match n.as_f64() {
            Some(0.0) => out.write_all(b"0"),
            Some(f) if n.is_f64() && f.fract() == 0.0 && f.abs() < 1e15 => {
                write!(out, "{}", f as i64)
            }
            _ => write!(out, "{n}"),
        },
        // JSON escapes only quotes, backslashes and control characters: text without them
        // (a floor plan's base64 image, megabytes of it) is written as it is.
        Value::String(text) if !needs_escapes(text) => {
            out.write_all(b"\"")?;
            out.write_all(text.as_bytes())?;
            out.write_all(b"\"")
        }
        other => Ok(serde_json::to_writer(&mut *out, other)?),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use irs_model::scenario::{Grouping, MAX_NAME_CHARS};

    /// The built-in small floor with a second IRS on its east wall.
    fn small_test_two_surfaces(grouping: Grouping) -> Scenario {
        let name = serde_json::to_value(grouping).expect("groupings serialise");
        Scenario::builtin_with("small-test", |v| {
            let mut first = v.as_object_mut().unwrap().remove("irs").unwrap();
            first["grouping"] = name.clone();
            let second = serde_json::json!({
                "center": [6.0, 2.0, 1.8], "normal": [-1.0, 0.0, 0.0],
                "nx_sub": 3, "nz_sub": 1, "elements_per_sub": 2, "grouping": name,
            });
            v["irss"] = serde_json::json!([first, second]);
        })
        .expect("built in")
        .expect("a valid two-surface variant")
    }

    const SMALL: &str = BUILTIN[2].1;

    /// A character JSON escapes is found on either side of the scan's 256-byte chunks.
    #[test]
    fn escapes_are_found_across_chunks() {
        for at in [0, 255, 256, 257, 1023] {
            for c in ['"', '\\', '\u{1f}'] {
                let mut text = "A".repeat(1024);
                text.replace_range(at..at + 1, &c.to_string());
                let mut out = Vec::new();
                write_canonical(&serde_json::Value::String(text.clone()), &mut out).unwrap();
                assert_eq!(out, serde_json::to_vec(&text).unwrap(), "{c:?} at {at}");
            }
        }
    }

    proptest::proptest! {
        /// Strings are written as serde_json writes them, whether or not they take the path
        /// for text without escapes.
        #[test]
        fn canonical_strings_are_serde_json_strings(text in "(\\PC|[\"\\\\\u{0}-\u{1f}\u{7f}])*") {
            let value = serde_json::json!({"k": text, "n": [1.5, 0.0, 2.0]});
            let mut out = Vec::new();
            write_canonical(&value, &mut out).unwrap();
            let expected = format!("{{\"k\":{},\"n\":[1.5,0,2]}}", serde_json::to_string(&text).unwrap());
            proptest::prop_assert_eq!(String::from_utf8(out).unwrap(), expected);
        }
    }

    #[test]
    fn builtin_scenarios_are_valid() {
        for (name, _) in BUILTIN {
            assert_eq!(Scenario::builtin(name).unwrap().name.as_deref(), Some(name));
        }
        assert!(Scenario::builtin("nope").is_none());
    }

    #[test]
    fn small_scenario_parses_and_grid_includes_both_walls() {
        let s = Scenario::from_json(SMALL).unwrap();
        let g = s.grid();
        assert_eq!(g.centre(0, 0), [s.room.x_min, s.room.y_min]);
        assert_eq!(g.centre(g.nx - 1, g.ny - 1), [s.room.x_max, s.room.y_max]);
    }

    /// Found by the fuzzer: a coordinate written with more digits than an f64 holds must parse
    /// to the correctly rounded f64, or its canonical form re-parses to another number and the
    /// scenario's id changes when its own document is registered again.
    #[test]
    fn the_canonical_form_parses_back_to_the_same_scenario() {
        let doc: serde_json::Value =
            serde_json::from_str(include_str!("../../../../scenarios/paper-multi-user.json"))
                .unwrap();
        let written = doc.to_string();
        let text = written.replacen(
            "\"v_max_mps\":1.0",
            "\"v_max_mps\":0.00018446744073709551615001",
            1,
        );
        assert_ne!(text, written);
        let first = Scenario::from_json(&text).unwrap();
        let again = Scenario::from_json(&first.canonical_json()).unwrap();
        assert_eq!(again.content_hash(), first.content_hash());
    }

    #[test]
    fn hash_ignores_key_order_formatting_and_written_defaults() {
        let a = Scenario::from_json(SMALL).unwrap();
        let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
        // Spell out a default and reformat.
        v["channel"] = serde_json::json!({"path_loss": "3gpp_inf_sh", "rician_k_db": 3.0});
        let b = Scenario::from_json(&serde_json::to_string_pretty(&v).unwrap()).unwrap();
        assert_eq!(a.content_hash(), b.content_hash());
        assert_eq!(a.content_hash().len(), 32);
        v["ap"]["tx_power_dbm"] = serde_json::json!(21.0);
        let c = Scenario::from_json(&v.to_string()).unwrap();
        assert_ne!(a.content_hash(), c.content_hash());
    }

    fn mutated(f: impl FnOnce(&mut serde_json::Value)) -> FieldError {
        let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
        f(&mut v);
        Scenario::from_json(&v.to_string()).unwrap_err()
    }

    #[test]
    fn errors_name_the_field() {
        type Mutation = Box<dyn FnOnce(&mut serde_json::Value)>;
        let cases: Vec<(Mutation, &str)> = vec![
            (Box::new(|v| v["room"]["bogus"] = 1.into()), "room.bogus"),
            // A missing field is named itself, not the object that lacks it.
            (
                Box::new(|v| {
                    v["mru"].as_object_mut().unwrap().remove("v_max_mps");
                }),
                "mru.v_max_mps",
            ),
            (
                Box::new(|v| {
                    v.as_object_mut().unwrap().remove("room");
                }),
                "room",
            ),
            // An explicit null is not "absent": it is rejected, naming the field.
            (Box::new(|v| v["irs"] = serde_json::Value::Null), "irs"),
            (
                Box::new(|v| v["irs"]["sub_pitch_m"] = serde_json::Value::Null),
                "irs.sub_pitch_m",
            ),
            (Box::new(|v| v["name"] = serde_json::Value::Null), "name"),
            // Obstacles stay in the room; the IRS hangs on a wall, facing into the room.
            (
                Box::new(|v| v["obstacles"][0]["center"] = serde_json::json!([5.8, 2.0])),
                "obstacles[0].center",
            ),
            (
                Box::new(|v| v["irs"]["center"] = serde_json::json!([3.0, 0.5, 2.0])),
                "irs.center",
            ),
            (
                Box::new(|v| {
                    v["irs"]["center"] = serde_json::json!([6.0, 2.0, 2.0]);
                    v["irs"]["normal"] = serde_json::json!([1.0, 0.0, 0.0]);
                }),
                "irs.normal",
            ),
            (
                Box::new(|v| v["obstacles"][0]["size"] = serde_json::json!([-1.0, 2.0])),
                "obstacles[0].size",
            ),
            (
                Box::new(|v| v["ap"]["position"] = v["obstacles"][0]["center"].clone()),
                "ap.position",
            ),
            (
                Box::new(|v| v["grid"]["resolution_m"] = 0.001.into()),
                "grid.resolution_m",
            ),
            (
                Box::new(|v| v["grid"]["resolution_m"] = 0.35.into()),
                "room.x_max",
            ),
            (
                Box::new(|v| v["irs"]["normal"] = serde_json::json!([0.0, 0.9, 0.0])),
                "irs.normal",
            ),
            (Box::new(|v| v["irs"]["nx_sub"] = 0.into()), "irs.nx_sub"),
            // The whole surface stays in the room: 2 × 2 tiles of 1.2 m around z = 2 m reach
            // past the 3 m ceiling; a 10³⁰⁸ m pitch (found by the fuzzer) past everything.
            (
                Box::new(|v| v["irs"]["sub_pitch_m"] = 1.2.into()),
                "irs.sub_pitch_m",
            ),
            (
                Box::new(|v| v["irs"]["sub_pitch_m"] = 1.00751e308.into()),
                "irs.sub_pitch_m",
            ),
            // Products that wrap around in 64 bits must not slip through the size limits.
            (
                Box::new(|v| {
                    v["irs"]["nx_sub"] = (1u64 << 32).into();
                    v["irs"]["nz_sub"] = (1u64 << 32).into();
                }),
                "irs.nx_sub",
            ),
            (
                Box::new(|v| v["irs"]["nz_sub"] = (1u64 << 63).into()),
                "irs.nx_sub",
            ),
            (
                Box::new(|v| v["irs"]["elements_per_sub"] = ((1u64 << 63) + 1).into()),
                "irs.elements_per_sub",
            ),
            (
                Box::new(|v| v["mru"]["v_max_mps"] = 0.into()),
                "mru.v_max_mps",
            ),
            // Sizes the engine would otherwise take on trust.
            (
                Box::new(|v| v["name"] = "n".repeat(MAX_NAME_CHARS + 1).into()),
                "name",
            ),
            (
                Box::new(|v| v["grid"]["resolution_m"] = 100.0.into()),
                "grid.resolution_m",
            ),
            (
                Box::new(|v| {
                    v["room"]["x_max"] = 20_000.0.into();
                    v["room"]["y_max"] = 0.5.into();
                    v["grid"]["resolution_m"] = 0.5.into();
                }),
                "grid.resolution_m",
            ),
            (
                Box::new(|v| v["room"]["x_min"] = (-1e300).into()),
                "room.x_min",
            ),
            (
                Box::new(|v| v["ap"]["carrier_ghz"] = (-2.0).into()),
                "ap.carrier_ghz",
            ),
            (
                Box::new(|v| v["srus"][0]["position"] = serde_json::json!([0.0, 0.0, -1.0])),
                "srus[0].position",
            ),
            (
                Box::new(|v| v["channel"]["path_loss"] = "free_space".into()),
                "channel.path_loss",
            ),
        ];
        for (mutate, field) in cases {
            let e = mutated(mutate);
            assert_eq!(e.field, field, "{e}");
        }
    }

    /// A surface that just fits (2 × 2 tiles of 1 m around z = 2 m under a 3 m ceiling, 2 m of
    /// a 6 m wall) is valid: the extent check has no margin beyond the wall tolerance.
    #[test]
    fn a_repeated_key_is_refused_not_taken_last() {
        // Written by hand: serde_json would keep the second `nx_sub` silently.
        let text = SMALL.replacen("\"irs\": {", "\"irs\": {\"nx_sub\": 1000, ", 1);
        assert_ne!(text, SMALL, "the edit applies");
        let e = Scenario::from_json(&text).unwrap_err();
        assert_eq!(
            (e.field.as_str(), e.reason.as_str()),
            ("irs", "duplicate key `nx_sub`")
        );
    }

    #[test]
    fn a_surface_that_just_fits_is_valid() {
        let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
        v["irs"]["sub_pitch_m"] = 1.0.into();
        assert!(Scenario::from_json(&v.to_string()).is_ok());
        v["irs"]["sub_pitch_m"] = 1.01.into();
        assert!(Scenario::from_json(&v.to_string()).is_err());
    }

    /// An IRS on an obstacle's side, facing away from it, is a valid mount.
    #[test]
    fn irs_may_hang_on_an_obstacle_face() {
        // The small room's obstacle spans x ∈ [2.5, 3.5], y ∈ [1, 3], 1.5 m high.
        let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
        v["irs"]["center"] = serde_json::json!([2.5, 2.0, 1.0]);
        v["irs"]["normal"] = serde_json::json!([-1.0, 0.0, 0.0]);
        assert!(Scenario::from_json(&v.to_string()).is_ok());
        v["irs"]["center"] = serde_json::json!([2.5, 2.0, 2.0]);
        let e = Scenario::from_json(&v.to_string()).unwrap_err();
        assert_eq!(
            e.field, "irs.center",
            "above the obstacle it hangs on nothing"
        );
    }

    #[test]
    fn ap_position_must_be_a_triple() {
        let e = mutated(|v| v["ap"]["position"] = serde_json::json!([0.0, 1.0]));
        assert_eq!(e.field, "ap.position");
        assert!(e.reason.contains("invalid length"), "{e}");
    }

    /// The canonical form of a scenario without walls or a floor plan does not mention them,
    /// so ids from before they existed stand (this id is the paper floor's since the start).
    #[test]
    fn scenarios_without_walls_or_floor_plans_keep_their_ids() {
        let s = Scenario::builtin("paper-single-user").unwrap();
        let canonical = s.canonical_json();
        assert!(!canonical.contains("walls") && !canonical.contains("floor_plan"));
        assert_eq!(s.content_hash(), "0f9d7233fc2ba13d34e5b5949a3e75f6");
    }

    /// A one-element `irss` is the same scenario as `irs`: same canonical form, same id.
    #[test]
    fn one_surface_is_one_surface_however_it_is_written() {
        let as_object = Scenario::builtin("small-test").unwrap();
        let as_list = Scenario::builtin_with("small-test", |v| {
            let irs = v.as_object_mut().unwrap().remove("irs").unwrap();
            v["irss"] = serde_json::json!([irs]);
        })
        .unwrap()
        .unwrap();
        assert_eq!(as_list.canonical_json(), as_object.canonical_json());
        assert_eq!(as_list, as_object);
        let two = small_test_two_surfaces(Grouping::Coherent);
        assert_eq!(two.surfaces().len(), 2);
        assert!(two.canonical_json().contains("\"irss\":["));
        let again = Scenario::from_json(&two.canonical_json()).unwrap();
        assert_eq!(again.content_hash(), two.content_hash());
    }

    #[test]
    fn surfaces_are_checked_one_by_one_and_together() {
        let two = |edit: fn(&mut serde_json::Value)| {
            let mut v = small_test_two_surfaces(Grouping::Coherent).to_json_value();
            edit(&mut v);
            Scenario::from_value(v).unwrap_err()
        };
        type Edit = fn(&mut serde_json::Value);
        let cases: [(Edit, &str); 4] = [
            (
                |v| v["irss"][1]["center"] = serde_json::json!([5.0, 2.0, 1.8]),
                "irss[1].center",
            ),
            (|v| v["irss"][0]["nx_sub"] = 0.into(), "irss[0].nx_sub"),
            (|v| v["irs"] = v["irss"][0].clone(), "irss"),
            // Within its own limits and the room (a 2 m row), beyond the sum's.
            (
                |v| {
                    v["irss"][1]["nx_sub"] = 1021.into();
                    v["irss"][1]["sub_pitch_m"] = 0.002.into();
                },
                "irss",
            ),
        ];
        for (edit, field) in cases {
            let e = two(edit);
            assert_eq!(e.field, field, "{e}");
        }
    }

    #[test]
    fn walls_are_checked_field_by_field() {
        let wall = |edit: fn(&mut serde_json::Value)| {
            mutated(|v| {
                v["walls"] = serde_json::json!([
                    {"from": [0.5, 1.0], "to": [1.5, 1.0], "thickness_m": 0.2, "height_m": 2.0}
                ]);
                edit(&mut v["walls"][0]);
            })
        };
        type Edit = fn(&mut serde_json::Value);
        let cases: [(Edit, &str); 5] = [
            (|w| w["thickness_m"] = 0.into(), "walls[0].thickness_m"),
            (|w| w["height_m"] = (-1).into(), "walls[0].height_m"),
            (|w| w["to"] = w["from"].clone(), "walls[0].to"),
            (
                |w| w["from"] = serde_json::json!([-3.0, 1.0]),
                "walls[0].from",
            ),
            (
                |w| w["from"] = serde_json::json!([0.5, 1.0, 0.0]),
                "walls[0].from",
            ),
        ];
        for (edit, field) in cases {
            assert_eq!(wall(edit).field, field);
        }
    }

    /// An IRS may hang on a wall at any angle, facing away from it; inside the wall, facing it
    /// or floating beside it is rejected naming the field.
    #[test]
    fn an_irs_may_hang_on_a_diagonal_wall() {
        // A wall from (1, 1) to (3, 3), 0.2 m thick: its north-west face passes through
        // (2, 2) + 0.1·(−1, 1)/√2.
        let h = 0.1 / 2f64.sqrt();
        let with_irs = |centre: [f64; 2], normal: [f64; 2]| {
            let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
            v["obstacles"] = serde_json::json!([]);
            v["walls"] = serde_json::json!([
                {"from": [1.0, 1.0], "to": [3.0, 3.0], "thickness_m": 0.2, "height_m": 2.5}
            ]);
            v["ap"]["position"] = serde_json::json!([0.5, 3.5, 2.0]);
            v["irs"]["center"] = serde_json::json!([centre[0], centre[1], 1.5]);
            v["irs"]["normal"] = serde_json::json!([normal[0], normal[1], 0.0]);
            Scenario::from_json(&v.to_string())
        };
        let n = [-(0.5f64.sqrt()), 0.5f64.sqrt()];
        assert!(with_irs([2.0 - h, 2.0 + h], n).is_ok());
        let field = |r: Result<Scenario, FieldError>| r.unwrap_err().field;
        assert_eq!(
            field(with_irs([2.0, 2.0], n)),
            "irs.center",
            "inside the wall"
        );
        assert_eq!(
            field(with_irs([2.0 - 3.0 * h, 2.0 + 3.0 * h], n)),
            "irs.center",
            "in the air"
        );
        // On the south-east face, facing north-west: into the wall (and the AP is behind it, so
        // the AP check speaks first unless the AP moves).
        let e = with_irs([2.0 + h, 2.0 - h], n).unwrap_err();
        assert_eq!(e.field, "irs.normal", "{e}");
    }

    #[test]
    fn floor_plan_errors_name_the_field() {
        use base64::Engine;
        let image = |bytes: &[u8]| base64::engine::general_purpose::STANDARD.encode(bytes);
        // 12 × 8 white pixels of 0.5 m from the room's corner cover the 6 m × 4 m room.
        let mut white = b"P5\n12 8\n255\n".to_vec();
        white.extend([254u8; 96]);
        let plan = serde_json::json!({
            "image": image(&white), "resolution": 0.5, "origin": [0.0, 0.0, 0.0], "negate": 0,
            "occupied_thresh": 0.65, "free_thresh": 0.25,
        });
        let with_plan = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
            v["floor_plan"] = plan.clone();
            edit(&mut v["floor_plan"]);
            Scenario::from_json(&v.to_string())
        };
        let s = with_plan(&|_| {}).unwrap();
        assert_eq!(s.floor_plan.as_ref().unwrap().obstacle_height_m, Some(3.0));
        type Edit<'a> = &'a dyn Fn(&mut serde_json::Value);
        let cases: [(Edit, &str); 7] = [
            (
                &|p| p["origin"] = serde_json::json!([0.0, 0.0]),
                "floor_plan.origin",
            ),
            (
                &|p| p["origin"] = serde_json::json!([0.5, 0.0, 0.0]),
                "floor_plan",
            ),
            (&|p| p["resolution"] = 0.25.into(), "floor_plan"),
            (&|p| p["image"] = "AAAA".into(), "floor_plan.image"),
            (&|p| p["negate"] = 2.into(), "floor_plan.negate"),
            (
                &|p| p["unknown_as"] = "maybe".into(),
                "floor_plan.unknown_as",
            ),
            (
                &|p| p["obstacle_height_m"] = 0.into(),
                "floor_plan.obstacle_height_m",
            ),
        ];
        for (edit, field) in cases {
            assert_eq!(with_plan(edit).unwrap_err().field, field);
        }
        let e =
            Scenario::from_value(serde_json::json!({"floor_plan": {"map": "m.yaml"}})).unwrap_err();
        assert_eq!(e.field, "floor_plan.map");
    }

    /// Ids taken together, the floor plan's image hashed once for those sharing it, are each
    /// scenario's SHA-256 of its canonical form: candidates differing after the image (the
    /// name) reuse the state, one differing before it (an AP) or holding another image does
    /// not, and a scenario without a floor plan is hashed whole.
    #[test]
    fn ids_taken_together_hash_each_canonical_form() {
        use base64::Engine;
        let image = |bytes: &[u8]| base64::engine::general_purpose::STANDARD.encode(bytes);
        let plan = |grey: u8| {
            let mut file = b"P5\n12 8\n255\n".to_vec();
            file.extend([grey; 96]);
            serde_json::json!({
                "image": image(&file), "resolution": 0.5, "origin": [0.0, 0.0, 0.0],
                "negate": 0, "occupied_thresh": 0.65, "free_thresh": 0.25,
            })
        };
        let with_plan = |grey: u8| {
            let mut v: serde_json::Value = serde_json::from_str(SMALL).unwrap();
            v["floor_plan"] = plan(grey);
            Scenario::from_json(&v.to_string()).unwrap()
        };
        let base = with_plan(254);
        let renamed = |name: &str| {
            let mut s = base.clone();
            s.name = Some(name.into());
            s
        };
        let [x, y, z] = base.access_points()[0].position;
        let moved_ap = base.with_ap_at(0, [x + 0.25, y, z]).unwrap();
        let plain = Scenario::from_json(SMALL).unwrap();
        let scenarios = [
            base.clone(),
            renamed("second"),
            renamed("third"),
            moved_ap,
            renamed("fourth"),
            with_plan(250),
            plain,
            renamed("fifth"),
        ];
        let refs: Vec<&Scenario> = scenarios.iter().collect();
        let ids = content_hashes(&refs);
        for (scenario, id) in scenarios.iter().zip(&ids) {
            assert_eq!(id, &hash_hex(scenario.canonical_json().as_bytes()));
            assert_eq!(id, &scenario.content_hash());
        }
        let distinct: std::collections::HashSet<&String> = ids.iter().collect();
        assert_eq!(distinct.len(), ids.len(), "{ids:?}");
    }

    #[test]
    fn snap_rejects_points_outside_the_room() {
        let s = Scenario::from_json(SMALL).unwrap();
        let g = s.grid();
        assert_eq!(g.snap(s.room.x_min, s.room.y_min), Some((0, 0)));
        assert_eq!(g.snap(s.room.x_max + 1.0, 0.0), None);
        assert_eq!(g.snap(f64::NAN, 0.0), None);
    }
}
