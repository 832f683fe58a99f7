//! Large JSON answers: a fleet plan serialised into one buffer sized up front
//! ([`serialize_sized`]), and a path answer's text (written by `irs_answers::path_json`, kept
//! for repeated queries) sent with its own `took_ms` after it ([`with_took_ms`]).

use axum::body::{Body, Bytes, HttpBody};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use http_body::{Frame, SizeHint};
use irs_answers::timing;
use serde::Serialize;
use std::convert::Infallible;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Instant;

use super::problem::ApiError;

/// `value` serialised into one buffer of about `capacity` bytes (sized by the caller so it is not
/// regrown and copied on the way to hundreds of kilobytes).
pub(crate) fn serialize_sized(
    value: &impl Serialize,
    capacity: usize,
) -> Result<Vec<u8>, ApiError> {
    let mut body = Vec::with_capacity(capacity);
    serde_json::to_writer(&mut body, value)
        .map_err(|e| ApiError::from(crate::app::Error::internal(e.to_string())))?;
    Ok(body)
}

/// A JSON answer from `open`, an object's text without its closing brace, closed with
/// `took_ms` (the milliseconds since `started`, to the microsecond) as its last field. The
/// two are sent as they are, one after the other: `open` is shared with the kept answers, and
/// joining them meant copying it (0.6 MB for a path of a thousand waypoints) for every reply.
pub(crate) fn with_took_ms(open: Bytes, started: Instant) -> Response {
    let mut close = Vec::with_capacity(32);
    timing::close_with_took_ms(&mut close, timing::took_ms(started));
    let body = Parts([Some(open), Some(Bytes::from(close))]);
    (
        [(header::CONTENT_TYPE, "application/json")],
        Body::new(body),
    )
        .into_response()
}

/// A body of two buffers sent in order, its length known (so sent with Content-Length).
struct Parts([Option<Bytes>; 2]);

impl HttpBody for Parts {
    type Data = Bytes;
    type Error = Infallible;

    fn poll_frame(
        mut self: Pin<&mut Self>,
        _: &mut Context<'_>,
    ) -> Poll<Option<Result<Frame<Bytes>, Infallible>>> {
        let next = self.0.iter_mut().find_map(Option::take);
        Poll::Ready(next.map(|part| Ok(Frame::data(part))))
    }

    fn is_end_stream(&self) -> bool {
        self.0.iter().all(Option::is_none)
    }

    fn size_hint(&self) -> SizeHint {
        SizeHint::with_exact(self.0.iter().flatten().map(|part| part.len() as u64).sum())
    }
}
