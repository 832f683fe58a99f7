//! Answers that say how long they took: every path, sweep and map answer carries `took_ms`,
//! the wall-clock time spent computing it (GraphHopper's `info.took`), the same field from the
//! CLI and from the API.

use serde::Serialize;
use std::time::Instant;

/// An answer body with its computing time appended as `took_ms`.
#[derive(Debug, Clone, Serialize)]
pub struct Timed<T> {
    /// The answer itself, its fields flattened into the body.
    #[serde(flatten)]
    pub answer: T,
    /// Milliseconds spent computing the answer (not sending it), to the microsecond.
    pub took_ms: f64,
}

impl<T> Timed<T> {
    /// `answer`, computed since `started`.
    pub fn since(started: Instant, answer: T) -> Self {
        Timed {
            answer,
            took_ms: took_ms(started),
        }
    }
}

/// Milliseconds since `started`, to the microsecond.
pub fn took_ms(started: Instant) -> f64 {
    started.elapsed().as_micros() as f64 / 1e3
}

/// Closes `open`, the text of a JSON object without its closing brace, with `took_ms` as its
/// last field: what [`Timed`] writes, for a body written as text (a path answer, or one kept
/// and sent again).
pub fn close_with_took_ms(open: &mut Vec<u8>, took_ms: f64) {
    open.extend_from_slice(br#","took_ms":"#);
    serde_json::to_writer(&mut *open, &took_ms).expect("a number serialises");
    open.push(b'}');
}
