//! Admission control for heavy queries: sweeps, paths and pictures of big maps, map bodies and
//! exports, Monte Carlo checks. They run on a rayon pool of their own, never on the async
//! runtime's threads (which must stay free for health checks and cheap queries) nor on the
//! global pool the map builds use (a check sharing it slowed a 1001² build 40-fold), at most
//! `workers` at once, with at most `queue` more waiting; one more is refused with 503 and
//! `Retry-After`.
//!
//! Work that grows with what a client sent (parsing a large JSON body, decoding its floor-plan
//! image, hashing and writing a big scenario, serialising it back) runs here too once it passes
//! [`INLINE_BYTES`] ([`QueryPool::run_sized`]): 32 clients sending 8 MiB bodies at once held
//! the runtime's threads for 1.8 s, and `/healthz` with them.
//!
//! A query is cancelled when its client goes: hyper drops the handler's future when the
//! connection closes, and dropping [`QueryPool::run`]'s future sets the work's cancellation
//! flag, which sweeps check per threshold and Monte Carlo checks per waypoint. The worker's
//! permit is held by the work itself, so a cancelled query still counts until it has stopped.

use crate::app::Error;
use irs_model::radiomap::Progress;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use tokio::sync::{Semaphore, oneshot};

/// Seconds a client refused for a full query queue is asked to wait: queries last from
/// milliseconds to a few seconds, so one second spreads retries without idling the pool.
const RETRY_AFTER_S: u64 = 1;

/// Bytes of input below which parsing, hashing or serialising runs on the async thread that
/// received it: 64 KiB of JSON parse in about 0.1 ms, less than the hand-off to a worker and
/// within tokio's budget between awaits; 8 MiB take 20–100 ms, which a health check must not
/// wait behind.
pub(crate) const INLINE_BYTES: usize = 64 * 1024;

pub(crate) struct QueryPool {
    threads: rayon::ThreadPool,
    permits: Arc<Semaphore>,
    waiting: AtomicUsize,
    queue_limit: usize,
}

/// Cancels the work when the query's future is dropped before the work ended (disarmed by
/// taking the progress out once it has).
struct CancelOnDrop(Option<Arc<Progress>>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        if let Some(progress) = &self.0 {
            progress.cancel();
        }
    }
}

/// Counts a query waiting for a permit for as long as it waits.
struct Waiting<'a>(&'a AtomicUsize);

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
        metrics::gauge!("irs_queries_waiting").decrement(1.0);
    }
}

impl QueryPool {
    pub fn new(workers: usize, queue_limit: usize) -> Result<Self, String> {
        let threads = rayon::ThreadPoolBuilder::new()
            .num_threads(workers)
            .thread_name(|k| format!("irs-query-{k}"))
            .start_handler(|_| crate::priority::lower_this_thread())
            .build()
            .map_err(|e| format!("query pool: {e}"))?;
        Ok(QueryPool {
            threads,
            permits: Arc::new(Semaphore::new(workers)),
            waiting: AtomicUsize::new(0),
            queue_limit,
        })
    }

    /// Runs `work` inline when the input it reads weighs under [`INLINE_BYTES`], else as a
    /// query (`what` names it in a 503 and the metrics).
    pub async fn run_sized<T: Send + 'static>(
        &self,
        what: &'static str,
        bytes: usize,
        work: impl FnOnce() -> T + Send + 'static,
    ) -> Result<T, Error> {
        if bytes < INLINE_BYTES {
            return Ok(work());
        }
        self.run(what, move |_| work()).await
    }

    /// Runs `work` on the query pool once a worker is free (503 when the queue is full). The
    /// work gets a [`Progress`] that is cancelled if this future is dropped first.
    pub async fn run<T: Send + 'static>(
        &self,
        what: &'static str,
        work: impl FnOnce(&Progress) -> T + Send + 'static,
    ) -> Result<T, Error> {
        let permit = match self.permits.clone().try_acquire_owned() {
            Ok(permit) => permit,
            Err(_) => {
                if self.waiting.fetch_add(1, Ordering::SeqCst) >= self.queue_limit {
                    self.waiting.fetch_sub(1, Ordering::SeqCst);
                    metrics::counter!("irs_queries_refused_total", "what" => what).increment(1);
                    return Err(Error::Busy {
                        what,
                        limit: self.queue_limit,
                        retry_after_s: RETRY_AFTER_S,
                    });
                }
                metrics::gauge!("irs_queries_waiting").increment(1.0);
                let _waiting = Waiting(&self.waiting);
                self.permits
                    .clone()
                    .acquire_owned()
                    .await
                    .map_err(|e| Error::internal(format!("query pool closed: {e}")))?
            }
        };
        let progress = Arc::new(Progress::default());
        let mut guard = CancelOnDrop(Some(progress.clone()));
        let (tx, rx) = oneshot::channel();
        self.threads.spawn(crate::tasks::bind(move || {
            // A panic must not reach rayon, whose default handler aborts the process.
            let answer = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&progress)));
            drop(permit);
            let _ = tx.send(answer);
        }));
        let answer = rx.await;
        guard.0 = None;
        match answer {
            Ok(Ok(answer)) => Ok(answer),
            Ok(Err(_)) => Err(Error::internal(format!("the {what} failed"))),
            Err(_) => Err(Error::internal(format!("the {what} worker stopped"))),
        }
    }
}

/// The bytes a JSON value's text takes, roughly (strings and numbers by their length, a few
/// bytes per punctuation), counted only up to `cap`: deciding where to parse a document must
/// cost far less than parsing it, so a 650 000-number array stops the count at `cap`.
pub(crate) fn json_weight(value: &serde_json::Value, cap: usize) -> usize {
    use serde_json::Value;
    let mut weight = 0;
    let mut stack = vec![value];
    while let Some(v) = stack.pop() {
        if weight >= cap {
            break;
        }
        weight += match v {
            Value::Null | Value::Bool(_) => 5,
            Value::Number(_) => 8,
            Value::String(s) => s.len() + 2,
            Value::Array(items) => {
                // Every item weighs at least 5 bytes: more than cap / 5 of them pass the cap.
                stack.extend(items.iter().take(cap / 5 + 1));
                2 + items.len()
            }
            Value::Object(fields) => {
                stack.extend(fields.values());
                2 + fields.keys().map(|k| k.len() + 4).sum::<usize>()
            }
        };
    }
    weight
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn json_weight_is_close_to_the_text_and_stops_at_its_cap() {
        let doc =
            json!({"name": "x".repeat(1000), "points": [[1.5, 2.0], [3.0, 4.25]], "on": true});
        let text = serde_json::to_string(&doc).unwrap().len();
        let weight = json_weight(&doc, usize::MAX);
        assert!(
            weight >= text * 9 / 10 && weight <= text * 2,
            "{weight} vs {text}"
        );
        let big = serde_json::Value::Array(vec![json!(0.123456); 1_000_000]);
        assert!(json_weight(&big, INLINE_BYTES) >= INLINE_BYTES);
        let small = json!([1, 2, 3]);
        assert!(json_weight(&small, INLINE_BYTES) < 64);
    }
}
