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
        let micros = started.elapsed().as_micros() as f64;
        Timed {
            answer,
            took_ms: micros / 1e3,
        }
    }
}
