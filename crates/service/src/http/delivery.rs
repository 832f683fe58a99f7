//! How answers leave the server: every answer body is handed to hyper in slices of at most
//! [`SLICE_BYTES`], so hyper asks for the next slice only once the previous one went out, and
//! two bounds follow from watching those asks:
//! - **memory**: the answers being sent at once hold at most `--answers-in-flight-mb` between
//!   them (answers under [`UNCOUNTED_BYTES`] aside); an answer that would exceed it is replaced
//!   by 503 `answers_in_flight` with `Retry-After` and freed at once. A client that stops
//!   reading otherwise pins its whole answer for as long as it keeps the socket.
//! - **stalls**: each connection's [`Connection`] records when one of its answers last made
//!   progress; the listener (`runtime::server`) closes a connection whose answers made none for
//!   `--write-timeout-s`, which frees them. This works the same for HTTP/1.1 (hyper stops asking
//!   when the socket's buffer is full) and HTTP/2 (it stops when the peer's window is closed).
//!
//! The layer sits inside compression, so the budget weighs the answer as built (what memory
//! holds), not its compressed size, which is unknown until the end.

use super::problem::ApiError;
use axum::body::{Body, Bytes, HttpBody};
use axum::extract::{Request, State};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use http_body::{Frame, SizeHint};
use std::pin::Pin;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::task::{Context, Poll};
use std::time::{Duration, Instant};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

/// Largest slice of an answer handed to hyper at once: small enough that a stalled client
/// shows as a stall within one socket buffer, large enough that slicing costs nothing
/// measurable (a 15.8 MB map body is 242 slices).
const SLICE_BYTES: usize = 64 * 1024;

/// Answers smaller than this are not weighed against the budget: health checks, problems and
/// path answers always go out, and what they can hold is bounded by connections × streams.
pub(crate) const UNCOUNTED_BYTES: u64 = 64 * 1024;

/// The budget is counted in KiB so that any budget fits the semaphore's permits.
const UNIT: u64 = 1024;

/// The server-wide budget of answer bytes in flight.
#[derive(Clone)]
pub(crate) struct Budget {
    permits: Arc<Semaphore>,
    units: u32,
}

impl Budget {
    /// A budget of `bytes` (at least one unit).
    pub fn new(bytes: u64) -> Self {
        let units = u32::try_from((bytes / UNIT).max(1))
            .unwrap_or(u32::MAX)
            .min(u32::try_from(Semaphore::MAX_PERMITS).unwrap_or(u32::MAX));
        Budget {
            permits: Arc::new(Semaphore::new(units as usize)),
            units,
        }
    }

    /// Room for an answer of `bytes`, or `None` when the answers in flight leave too little.
    /// An answer larger than the whole budget takes all of it: it goes out alone.
    fn reserve(&self, bytes: u64) -> Option<OwnedSemaphorePermit> {
        let units = u32::try_from(bytes.div_ceil(UNIT))
            .unwrap_or(u32::MAX)
            .min(self.units);
        self.permits.clone().try_acquire_many_owned(units).ok()
    }

    /// The budget in bytes, as configured (rounded to KiB).
    pub fn bytes(&self) -> u64 {
        u64::from(self.units) * UNIT
    }
}

/// What one connection's answers are doing, shared by the listener that watches the
/// connection and the bodies that go out on it (a request extension carries it here).
pub(crate) struct Connection {
    epoch: Instant,
    /// When a request last started or ended, or an answer last moved (ms since `epoch`).
    last_activity_ms: AtomicU64,
    /// When an answer last moved on this connection (ms since `epoch`).
    last_progress_ms: AtomicU64,
    requests: AtomicUsize,
    bodies: AtomicUsize,
}

/// What the listener should do with a connection, judged by [`Connection::state`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Phase {
    /// A request is being answered, or an answer is moving.
    Busy,
    /// Nothing in flight for this long: HTTP/2 PINGs and stray bytes do not count.
    Idle(Duration),
    /// Answers are going out and the last moved this long ago (a client that stopped reading
    /// makes this grow).
    Sending(Duration),
}

impl Connection {
    pub fn new() -> Self {
        Connection {
            epoch: Instant::now(),
            last_activity_ms: AtomicU64::new(0),
            last_progress_ms: AtomicU64::new(0),
            requests: AtomicUsize::new(0),
            bodies: AtomicUsize::new(0),
        }
    }

    fn now_ms(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    fn since(&self, stamp: &AtomicU64) -> Duration {
        Duration::from_millis(self.now_ms().saturating_sub(stamp.load(Ordering::Relaxed)))
    }

    fn touch(&self) {
        self.last_activity_ms
            .store(self.now_ms(), Ordering::Relaxed);
    }

    fn moved(&self) {
        let now = self.now_ms();
        self.last_progress_ms.store(now, Ordering::Relaxed);
        self.last_activity_ms.store(now, Ordering::Relaxed);
    }

    /// Counts a request in flight on this connection until the guard drops.
    pub fn request(self: &Arc<Self>) -> RequestGuard {
        self.requests.fetch_add(1, Ordering::Relaxed);
        self.touch();
        RequestGuard(self.clone())
    }

    /// What the connection is doing now.
    pub fn state(&self) -> Phase {
        if self.bodies.load(Ordering::Relaxed) > 0 {
            return Phase::Sending(self.since(&self.last_progress_ms));
        }
        if self.requests.load(Ordering::Relaxed) > 0 {
            return Phase::Busy;
        }
        Phase::Idle(self.since(&self.last_activity_ms))
    }
}

/// A request in flight (see [`Connection::request`]).
pub(crate) struct RequestGuard(Arc<Connection>);

impl Drop for RequestGuard {
    fn drop(&mut self) {
        self.0.requests.fetch_sub(1, Ordering::Relaxed);
        self.0.touch();
    }
}

/// The middleware: weighs the answer against the budget and hands it out in slices, watched
/// by its connection.
pub(crate) async fn deliver(State(budget): State<Budget>, req: Request, next: Next) -> Response {
    let connection = req.extensions().get::<Arc<Connection>>().cloned();
    let response = next.run(req).await;
    let hint = response.body().size_hint();
    let bytes = hint.exact().unwrap_or(hint.lower());
    let permit = if bytes >= UNCOUNTED_BYTES {
        match budget.reserve(bytes) {
            Some(permit) => Some(Held::new(permit, bytes)),
            None => {
                metrics::counter!("irs_answers_refused_in_flight_total").increment(1);
                tracing::warn!(
                    bytes,
                    budget = budget.bytes(),
                    "answer refused: the answers in flight fill the budget"
                );
                return ApiError::answers_in_flight(budget.bytes()).into_response();
            }
        }
    } else {
        None
    };
    let (parts, body) = response.into_parts();
    let sliced = Sliced::new(body, permit, connection, hint);
    Response::from_parts(parts, Body::new(sliced))
}

/// An answer's share of the budget, shown in `irs_answers_in_flight_bytes` while held.
struct Held {
    _permit: OwnedSemaphorePermit,
    bytes: u64,
}

impl Held {
    fn new(permit: OwnedSemaphorePermit, bytes: u64) -> Self {
        metrics::gauge!("irs_answers_in_flight_bytes").increment(bytes as f64);
        Held {
            _permit: permit,
            bytes,
        }
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        metrics::gauge!("irs_answers_in_flight_bytes").decrement(self.bytes as f64);
    }
}

/// An answer body handed out in slices of at most [`SLICE_BYTES`], holding its share of the
/// budget until its last byte is handed over (or it is dropped with its connection).
struct Sliced {
    inner: Body,
    /// The rest of a frame larger than a slice.
    rest: Bytes,
    permit: Option<Held>,
    connection: Option<Arc<Connection>>,
    hint: SizeHint,
    done: bool,
}

impl Sliced {
    fn new(
        inner: Body,
        permit: Option<Held>,
        connection: Option<Arc<Connection>>,
        hint: SizeHint,
    ) -> Self {
        if let Some(c) = &connection {
            c.bodies.fetch_add(1, Ordering::Relaxed);
            c.moved();
        }
        Sliced {
            inner,
            rest: Bytes::new(),
            permit,
            connection,
            hint,
            done: false,
        }
    }

    fn next_slice(&mut self) -> Frame<Bytes> {
        let n = self.rest.len().min(SLICE_BYTES);
        if let Some(c) = &self.connection {
            c.moved();
        }
        Frame::data(self.rest.split_to(n))
    }

    /// The last byte went out (or the body failed): the budget and the connection let go now,
    /// not when hyper drops the body.
    fn finish(&mut self) {
        if !self.done {
            self.done = true;
            self.permit = None;
            if let Some(c) = &self.connection {
                c.bodies.fetch_sub(1, Ordering::Relaxed);
                c.moved();
            }
        }
    }
}

impl HttpBody for Sliced {
    type Data = Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Self::Error>>> {
        if !self.rest.is_empty() {
            return Poll::Ready(Some(Ok(self.next_slice())));
        }
        match Pin::new(&mut self.inner).poll_frame(cx) {
            Poll::Ready(Some(Ok(frame))) => match frame.into_data() {
                Ok(data) => {
                    self.rest = data;
                    Poll::Ready(Some(Ok(self.next_slice())))
                }
                Err(trailers) => Poll::Ready(Some(Ok(trailers))),
            },
            Poll::Ready(Some(Err(e))) => {
                self.finish();
                Poll::Ready(Some(Err(e)))
            }
            Poll::Ready(None) => {
                self.finish();
                Poll::Ready(None)
            }
            Poll::Pending => Poll::Pending,
        }
    }

    fn is_end_stream(&self) -> bool {
        self.rest.is_empty() && self.inner.is_end_stream()
    }

    fn size_hint(&self) -> SizeHint {
        // Unchanged by slicing: Content-Length stays what the handler's body said.
        if self.done {
            SizeHint::with_exact(0)
        } else {
            self.hint
        }
    }
}

impl Drop for Sliced {
    fn drop(&mut self) {
        self.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use http_body_util::BodyExt;

    #[tokio::test]
    async fn slices_rebuild_the_body_and_release_the_budget() {
        let budget = Budget::new(1024 * 1024);
        let connection = Arc::new(Connection::new());
        let data: Vec<u8> = (0..200_000u32).map(|k| (k % 251) as u8).collect();
        let body = Body::from(data.clone());
        let hint = body.size_hint();
        let permit = budget
            .reserve(data.len() as u64)
            .map(|p| Held::new(p, 200_000));
        assert!(permit.is_some());
        assert_eq!(budget.permits.available_permits(), 1024 - 196);
        let mut sliced = Sliced::new(body, permit, Some(connection.clone()), hint);
        assert_eq!(sliced.size_hint().exact(), Some(200_000));
        assert!(matches!(connection.state(), Phase::Sending(_)));
        let mut got = Vec::new();
        let mut slices = 0;
        while let Some(frame) = sliced.frame().await {
            let data = frame.unwrap().into_data().unwrap();
            assert!(data.len() <= SLICE_BYTES);
            got.extend_from_slice(&data);
            slices += 1;
        }
        assert_eq!(got, data);
        assert_eq!(slices, 4, "200 000 bytes in 64 KiB slices");
        // Released at the last byte, before the body is dropped.
        assert_eq!(budget.permits.available_permits(), 1024);
        assert!(matches!(connection.state(), Phase::Idle(_)));
        drop(sliced);
        assert_eq!(connection.bodies.load(Ordering::Relaxed), 0);
    }

    #[test]
    fn the_budget_refuses_past_its_bytes_and_lets_a_huge_answer_go_alone() {
        let budget = Budget::new(1024 * 1024);
        let first = budget.reserve(700 * 1024).unwrap();
        assert!(budget.reserve(400 * 1024).is_none());
        assert!(budget.reserve(300 * 1024).is_some());
        drop(first);
        // Larger than the whole budget: it takes all of it, and only when nothing else holds any.
        let huge = budget.reserve(10 * 1024 * 1024).unwrap();
        assert!(budget.reserve(UNIT).is_none());
        drop(huge);
        assert!(budget.reserve(UNIT).is_some());
    }

    #[test]
    fn a_connection_with_an_unread_answer_stalls_and_an_empty_one_idles() {
        let connection = Arc::new(Connection::new());
        std::thread::sleep(Duration::from_millis(20));
        assert!(matches!(connection.state(), Phase::Idle(d) if d >= Duration::from_millis(20)));
        let request = connection.request();
        assert_eq!(connection.state(), Phase::Busy);
        let body = Sliced::new(
            Body::from("x"),
            None,
            Some(connection.clone()),
            SizeHint::with_exact(1),
        );
        drop(request);
        std::thread::sleep(Duration::from_millis(20));
        assert!(matches!(connection.state(), Phase::Sending(d) if d >= Duration::from_millis(20)));
        drop(body);
        assert!(matches!(connection.state(), Phase::Idle(_)));
    }
}
