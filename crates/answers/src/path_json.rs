//! A path answer's JSON body, the one `irs-planner plan` prints and `POST /v1/paths` sends,
//! written by hand.
//!
//! A path answer is mostly its waypoints: a thousand on a large map, each a dozen fields and
//! the phases of every surface. Through serde's derived serialisers a waypoint cost about
//! 250 ns besides its phases: each key escaped byte by byte, each piece one call of the writer
//! copying a few bytes, the flattened configuration a map of its own; and the phases, which
//! serde could only take as a raw value, a string of their own copied once more. Here the keys
//! are constants and the numbers are written by the formatters serde_json itself uses (zmij
//! for floats, itoa for integers, `null` for a float that is not finite), so the text is the
//! one the derived serialisers wrote, byte for byte; the rest of the body (its ends, handovers
//! and Monte Carlo report), written once a body, goes through serde.

use crate::path::CheckedPath;
use crate::phase_text::SurfacePhases;
use irs_model::planner::{PathAnswer, Waypoint};
use serde::Serialize;

impl CheckedPath {
    /// The body as JSON text: one object, its fields in the order of openapi.yaml's
    /// `PathAnswer` (the answer's, then `monte_carlo` when there is one).
    pub fn to_json(&self) -> Vec<u8> {
        let path = &self.path;
        let mut out = Vec::with_capacity(capacity(path));
        out.extend_from_slice(br#"{"map_id":"#);
        value(&mut out, &path.map_id);
        field(&mut out, "unit", path.unit.symbol());
        field(&mut out, "threshold", &path.threshold);
        field(&mut out, "feasible", &path.feasible);
        field(&mut out, "reason", &path.reason);
        field(&mut out, "path_shape", &path.path_shape);
        field(&mut out, "distance_m", &path.distance_m);
        field(&mut out, "travel_time_s", &path.travel_time_s);
        field(
            &mut out,
            "max_feasible_threshold",
            &path.max_feasible_threshold,
        );
        field(&mut out, "start", &path.start);
        field(&mut out, "goal", &path.goal);
        field(&mut out, "frame_id", &path.frame_id);
        out.extend_from_slice(br#","waypoints":["#);
        let mut numbers = Numbers::default();
        for (k, waypoint) in path.waypoints.iter().enumerate() {
            if k > 0 {
                out.push(b',');
            }
            numbers.waypoint(&mut out, waypoint);
        }
        out.push(b']');
        field(&mut out, "vertices", &path.vertices);
        field(&mut out, "handovers", &path.handovers);
        if let Some(report) = &self.monte_carlo {
            field(&mut out, "monte_carlo", report);
        }
        out.push(b'}');
        out
    }
}

/// About the bytes of `path`'s body, so that the buffer is not regrown (and copied) a dozen
/// times on the way to hundreds of kilobytes: ~220 bytes per waypoint's other fields and its
/// phases' text, taken as the first waypoint's for every one. A path's waypoints hold the same
/// surfaces, written alike (a rate map's waypoint written in full instead of rounded aside,
/// which the buffer grows for); summing every waypoint's hint cost a pass over all their
/// phases' memory, 3 % of the body's time.
fn capacity(path: &PathAnswer<SurfacePhases>) -> usize {
    let phases = path
        .waypoints
        .first()
        .map_or(0, |w| w.config.phases.json_len_hint());
    512 + path.waypoints.len() * (220 + phases)
}

/// Appends `,"key":` and `value` as serde_json writes it. `key` needs no escaping.
fn field(out: &mut Vec<u8>, key: &str, value: &(impl Serialize + ?Sized)) {
    debug_assert!(key.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_'));
    out.extend_from_slice(b",\"");
    out.extend_from_slice(key.as_bytes());
    out.extend_from_slice(b"\":");
    self::value(out, value);
}

/// Appends `value` as serde_json writes it.
fn value(out: &mut Vec<u8>, value: &(impl Serialize + ?Sized)) {
    // Into a vector, only a type that cannot be written as JSON (a map with keys that are not
    // strings) fails, and an answer has none.
    serde_json::to_writer(out, value).expect("answers serialise");
}

/// The number formatters' buffers, kept across a body's waypoints, and the text of the last
/// x, y and heading written: consecutive waypoints often share them (the heading along every
/// straight run, x or y along the grid's axes), and copying a text is cheaper than writing
/// the shortest decimal of a double again (≈ 13 ns).
#[derive(Default)]
struct Numbers {
    float: zmij::Buffer,
    integer: itoa::Buffer,
    x: LastFloat,
    y: LastFloat,
    yaw: LastFloat,
}

/// A float and its text, as last written.
#[derive(Default)]
struct LastFloat {
    bits: Option<u64>,
    len: usize,
    text: [u8; SHORT],
}

impl Numbers {
    /// Appends one waypoint's object: its pose, value and time, then its configuration (the
    /// serving AP, the phases, and on rate maps the power split and decoding order).
    fn waypoint(&mut self, out: &mut Vec<u8>, w: &Waypoint<SurfacePhases>) {
        // The fields before the phases are written through a cursor in room reserved once:
        // through the vector, every key and number checked the room and stored the length, and
        // each byte stored could have changed the vector (a u8 pointer aliases anything), so its
        // pointer and length were loaded again after each.
        out.reserve(FIELDS_ROOM);
        let base = out.as_mut_ptr();
        // SAFETY: the writes below, the keys (71 bytes) and nine numbers of at most SHORT bytes,
        // stay within the FIELDS_ROOM bytes reserved, and the length counts only the bytes
        // written.
        unsafe {
            let mut at = base.add(out.len());
            at = put(at, br#"{"x":"#);
            at = put_short(at, Self::repeated(&mut self.float, &mut self.x, w.x));
            at = put(at, br#","y":"#);
            at = put_short(at, Self::repeated(&mut self.float, &mut self.y, w.y));
            at = put(at, br#","i":"#);
            at = put_short(at, self.integer.format(w.i).as_bytes());
            at = put(at, br#","j":"#);
            at = put_short(at, self.integer.format(w.j).as_bytes());
            at = put(at, br#","value":"#);
            at = put_short(at, Self::float_text(&mut self.float, w.value));
            at = put(at, br#","yaw_rad":"#);
            at = put_short(
                at,
                Self::repeated(&mut self.float, &mut self.yaw, w.yaw_rad),
            );
            at = put(at, br#","distance_m":"#);
            at = put_short(at, Self::float_text(&mut self.float, w.distance_m));
            at = put(at, br#","time_s":"#);
            at = put_short(at, Self::float_text(&mut self.float, w.time_s));
            at = put(at, br#","ap":"#);
            at = put_short(at, self.integer.format(w.config.ap).as_bytes());
            at = put(at, b",");
            out.set_len(at.offset_from(base) as usize);
        }
        w.config.phases.write_field(out);
        if let Some(power) = &w.config.power_w {
            field(out, "power_w", power);
        }
        if let Some(order) = &w.config.decoding_order {
            field(out, "decoding_order", order);
        }
        out.push(b'}');
    }

    /// `v` as serde_json writes an f64: its shortest round-trip decimal, `null` if not finite.
    fn float_text(buffer: &mut zmij::Buffer, v: f64) -> &[u8] {
        if v.is_finite() {
            buffer.format_finite(v).as_bytes()
        } else {
            b"null"
        }
    }

    /// `v` as [`Numbers::float_text`] writes it, from `last` when it holds the same double.
    fn repeated<'a>(buffer: &mut zmij::Buffer, last: &'a mut LastFloat, v: f64) -> &'a [u8] {
        if last.bits != Some(v.to_bits()) {
            let text = Self::float_text(buffer, v);
            // SAFETY: a float's text is at most SHORT bytes, the room of `last.text`.
            unsafe { copy_short(text, last.text.as_mut_ptr()) };
            last.len = text.len();
            last.bits = Some(v.to_bits());
        }
        &last.text[..last.len]
    }
}

/// Room for a waypoint's fields before its phases: their keys and commas (71 bytes) and nine
/// numbers (x, y, i, j, value, yaw, distance, time, AP).
const FIELDS_ROOM: usize = 71 + 9 * SHORT;

/// Writes `bytes` (a key: its length a constant once inlined, so the copy is a few stores) at
/// `at`; returns the byte after them.
///
/// # Safety
/// `at` is valid for writing `bytes.len()` bytes.
#[inline(always)]
unsafe fn put(at: *mut u8, bytes: &[u8]) -> *mut u8 {
    unsafe {
        std::ptr::copy_nonoverlapping(bytes.as_ptr(), at, bytes.len());
        at.add(bytes.len())
    }
}

/// Writes a number's `text`, at most [`SHORT`] bytes, at `at` ([`copy_short`]); returns the
/// byte after it.
///
/// # Safety
/// `text.len() <= SHORT`, and `at` is valid for writing `text.len()` bytes.
#[inline(always)]
unsafe fn put_short(at: *mut u8, text: &[u8]) -> *mut u8 {
    unsafe {
        copy_short(text, at);
        at.add(text.len())
    }
}

/// The longest number text written: an f64's shortest decimal (zmij: "-1.2345678901234567e-308"
/// is 24 bytes) or a usize's digits (20).
const SHORT: usize = 24;

/// Copies `text`, at most [`SHORT`] bytes, to `to` in a few loads and stores that may overlap,
/// inline. A number's text has a different length each time, so the copies it was written
/// with became calls of the C library's memmove, whose dispatch on the length cost more than
/// the copy: 12 % of a path body's time went there (perf, bench `path_answer`).
///
/// # Safety
/// `text.len() <= SHORT`, and `to` is valid for writing `text.len()` bytes.
#[inline(always)]
unsafe fn copy_short(text: &[u8], to: *mut u8) {
    use std::ptr::{read_unaligned as load, write_unaligned as store};
    let n = text.len();
    debug_assert!(n <= SHORT);
    let from = text.as_ptr();
    // SAFETY: every load lies within `text` and every store within the n bytes at `to`:
    // with 8 ≤ n ≤ 24, the words at 0, min(n, 16) − 8 and n − 8 cover [0, n); with 4 ≤ n < 8,
    // the halves at 0 and n − 4 do; with 0 < n < 4, the bytes at 0, n / 2 and n − 1.
    unsafe {
        if n >= 8 {
            let middle = n.min(16) - 8;
            let (a, b, c) = (
                load(from.cast::<u64>()),
                load(from.add(middle).cast::<u64>()),
                load(from.add(n - 8).cast::<u64>()),
            );
            store(to.cast::<u64>(), a);
            store(to.add(middle).cast::<u64>(), b);
            store(to.add(n - 8).cast::<u64>(), c);
        } else if n >= 4 {
            let (a, b) = (
                load(from.cast::<u32>()),
                load(from.add(n - 4).cast::<u32>()),
            );
            store(to.cast::<u32>(), a);
            store(to.add(n - 4).cast::<u32>(), b);
        } else if n > 0 {
            // A loop here would be turned back into a call of memcpy.
            *to = *from;
            *to.add(n / 2) = *from.add(n / 2);
            *to.add(n - 1) = *from.add(n - 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::path::{check, write_phases};
    use crate::phase_text::{PhaseFormat, PhasePrecision};
    use crate::scenario::ScenarioDocument;
    use irs_model::phases::PhaseMode;
    use irs_model::planner::{self, PathOptions, PathShape, Threshold};
    use irs_model::radiomap::{MapKey, Progress};
    use irs_model::rate::Access;
    use irs_model::scenario::Scenario;
    use serde_json::{Value, json};

    fn text(value: &(impl Serialize + ?Sized)) -> String {
        serde_json::to_string(value).unwrap()
    }

    /// The body as serde_json writes each value, joined in the documented order: the
    /// reference the hand-written body must equal byte for byte.
    fn reference(checked: &CheckedPath) -> String {
        let p = &checked.path;
        let waypoints: Vec<String> = p
            .waypoints
            .iter()
            .map(|w| {
                let c = &w.config;
                let phases = match &c.phases {
                    SurfacePhases::Codes(codes) => format!(r#""irs_phase_codes":{}"#, text(codes)),
                    other => format!(r#""irs_phases_rad":{}"#, text(other.radians().as_slice())),
                };
                let mut rate = String::new();
                if let Some(power) = &c.power_w {
                    rate += &format!(r#","power_w":{}"#, text(power));
                }
                if let Some(order) = &c.decoding_order {
                    rate += &format!(r#","decoding_order":{}"#, text(order));
                }
                format!(
                    r#"{{"x":{},"y":{},"i":{},"j":{},"value":{},"yaw_rad":{},"distance_m":{},"time_s":{},"ap":{},{phases}{rate}}}"#,
                    text(&w.x),
                    text(&w.y),
                    text(&w.i),
                    text(&w.j),
                    text(&w.value),
                    text(&w.yaw_rad),
                    text(&w.distance_m),
                    text(&w.time_s),
                    text(&c.ap),
                )
            })
            .collect();
        let monte_carlo = checked
            .monte_carlo
            .as_ref()
            .map(|r| format!(r#","monte_carlo":{}"#, text(r)))
            .unwrap_or_default();
        format!(
            r#"{{"map_id":{},"unit":{},"threshold":{},"feasible":{},"reason":{},"path_shape":{},"distance_m":{},"travel_time_s":{},"max_feasible_threshold":{},"start":{},"goal":{},"frame_id":{},"waypoints":[{}],"vertices":{},"handovers":{}{monte_carlo}}}"#,
            text(&p.map_id),
            text(p.unit.symbol()),
            text(&p.threshold),
            text(&p.feasible),
            text(&p.reason),
            text(&p.path_shape),
            text(&p.distance_m),
            text(&p.travel_time_s),
            text(&p.max_feasible_threshold),
            text(&p.start),
            text(&p.goal),
            text(&p.frame_id),
            waypoints.join(","),
            text(&p.vertices),
            text(&p.handovers),
        )
    }

    fn scenario(name: &str, edit: impl FnOnce(&mut Value)) -> Scenario {
        let mut doc: Value = serde_json::from_str(
            &std::fs::read_to_string(format!(
                "{}/../../scenarios/{name}.json",
                env!("CARGO_MANIFEST_DIR")
            ))
            .unwrap(),
        )
        .unwrap();
        edit(&mut doc);
        Scenario::from_value(doc).unwrap()
    }

    /// Gain maps with one AP and two (handovers), grid and any-angle paths, an infeasible
    /// query, rate maps (NOMA and OMA: powers and decoding orders), every phase format and a
    /// Monte Carlo report: each body equals, byte for byte, the reference joined from
    /// serde_json's text of each value, and reads back as JSON.
    #[test]
    fn bodies_are_what_serde_json_writes_for_each_value() {
        let one_ap = scenario("paper-single-user", |_| {});
        let two_aps = scenario("paper-single-user", |doc| {
            let mut second = doc["ap"].clone();
            second["position"] = json!([-9.5, -9.5, 2.0]);
            doc["aps"] = json!([doc["ap"].take(), second]);
            doc.as_object_mut().unwrap().remove("ap");
        });
        let srus = scenario("paper-multi-user", |doc| {
            doc["grid"]["resolution_m"] = 1.0.into();
        });
        let mut maps = Vec::new();
        for s in [&one_ap, &two_aps] {
            let key = MapKey::gain("test", s, PhaseMode::Continuous).unwrap();
            maps.push((s, crate::map::build(s, &key, &Progress::default()).unwrap()));
        }
        for access in [Access::Noma, Access::Oma] {
            let key = MapKey::rate("test", &srus, PhaseMode::Continuous, access).unwrap();
            maps.push((
                &srus,
                crate::map::build(&srus, &key, &Progress::default()).unwrap(),
            ));
        }
        let formats = [
            (PhaseFormat::Radians, PhasePrecision::TenthMilli),
            (PhaseFormat::Radians, PhasePrecision::Centi),
            (PhaseFormat::Radians, PhasePrecision::Full),
            (PhaseFormat::Codes, PhasePrecision::TenthMilli),
        ];
        let (mut handovers, mut powers, mut infeasible, mut checked_once) = (0, 0, 0, false);
        for (s, map) in &maps {
            let unit = map.native_unit();
            for (shape, threshold) in [
                (PathShape::Grid, Threshold::Max),
                (PathShape::AnyAngle, Threshold::Max),
                (PathShape::Grid, Threshold::Value(1e9)),
            ] {
                let options = PathOptions {
                    shape,
                    ..PathOptions::default()
                };
                let path =
                    planner::plan(map, unit, options, [-8.0, -8.0], [8.0, 8.0], threshold, 1.0)
                        .unwrap();
                for (format, precision) in formats {
                    let written = write_phases(s, map, path.clone(), format, precision);
                    let monte_carlo = (written.feasible && !checked_once).then(|| {
                        checked_once = true;
                        check(s, map, &written, 8, 1, &Progress::default()).unwrap()
                    });
                    handovers += written.handovers.len();
                    infeasible += usize::from(!written.feasible);
                    powers += written
                        .waypoints
                        .iter()
                        .filter(|w| w.config.decoding_order.is_some())
                        .count();
                    let checked = CheckedPath {
                        path: written,
                        monte_carlo,
                    };
                    let body = String::from_utf8(checked.to_json()).unwrap();
                    assert_eq!(
                        body,
                        reference(&checked),
                        "{format:?} {precision:?} {shape:?}"
                    );
                    let read: Value = serde_json::from_str(&body).unwrap();
                    assert_eq!(read["unit"], json!(unit.symbol()));
                }
            }
        }
        assert!(
            handovers > 0 && powers > 0 && infeasible > 0 && checked_once,
            "every part exercised: {handovers} handovers, {powers} decoding orders, \
             {infeasible} infeasible"
        );
    }

    /// Every length a number's text can have is copied whole, and nothing past it.
    #[test]
    fn short_copies_copy_every_length_exactly() {
        let text: Vec<u8> = (b'a'..).take(SHORT).collect();
        for n in 0..=SHORT {
            let mut to = [b'.'; SHORT + 1];
            unsafe { copy_short(&text[..n], to.as_mut_ptr()) };
            assert_eq!(&to[..n], &text[..n], "length {n}");
            assert!(
                to[n..].iter().all(|&b| b == b'.'),
                "length {n} wrote past its end"
            );
            let mut out = [b'.'; SHORT + 2];
            let end = unsafe { put_short(out.as_mut_ptr().add(1), &text[..n]) };
            assert_eq!(end as usize - out.as_ptr() as usize, 1 + n);
            assert_eq!(&out[1..1 + n], &text[..n]);
        }
    }

    /// A waypoint of the longest numbers in every field is written within the room reserved
    /// for its fields, as serde_json writes each value.
    #[test]
    fn the_longest_numbers_fit_the_fields_room() {
        // 24 bytes, the longest shortest decimal of an f64, and 20 digits, usize::MAX's.
        let long = -1.2345678901234567e-308;
        assert_eq!(text(&long).len(), SHORT);
        let waypoint = Waypoint {
            x: long,
            y: long,
            i: usize::MAX,
            j: usize::MAX,
            value: long,
            yaw_rad: long,
            distance_m: long,
            time_s: long,
            config: irs_model::radiomap::CellConfig {
                ap: usize::MAX,
                phases: SurfacePhases::Radians(Default::default()),
                power_w: None,
                decoding_order: None,
            },
        };
        let mut out = b"[".to_vec();
        Numbers::default().waypoint(&mut out, &waypoint);
        let body = String::from_utf8(out).unwrap();
        let fields = body.find(r#""irs_phases_rad""#).unwrap() - 1;
        assert!(fields <= FIELDS_ROOM, "{fields} bytes: {body}");
        let (n, x) = (text(&usize::MAX), text(&long));
        assert_eq!(
            body,
            format!(
                r#"[{{"x":{x},"y":{x},"i":{n},"j":{n},"value":{x},"yaw_rad":{x},"distance_m":{x},"time_s":{x},"ap":{n},"irs_phases_rad":[]}}"#
            )
        );
    }

    /// A float that is not finite is written as serde_json writes it, `null`, whether new or
    /// repeated.
    #[test]
    fn floats_not_finite_are_null() {
        let mut out = Vec::new();
        let mut numbers = Numbers::default();
        for v in [f64::NAN, f64::INFINITY, -0.0, 1e-7, 0.1 + 0.2] {
            out.extend_from_slice(Numbers::float_text(&mut numbers.float, v));
            out.push(b' ');
            out.extend_from_slice(text(&v).as_bytes());
            out.push(b'|');
            out.extend_from_slice(Numbers::repeated(&mut numbers.float, &mut numbers.x, v));
            out.push(b' ');
            out.extend_from_slice(text(&v).as_bytes());
            out.push(b'|');
        }
        for pair in String::from_utf8(out).unwrap().split_terminator('|') {
            let (ours, serde) = pair.split_once(' ').unwrap();
            assert_eq!(ours, serde);
        }
    }
}
