//! Large JSON answers (paths, fleet plans), written straight into one buffer sized up front,
//! and closed with their own `took_ms`.

use axum::http::header;
use axum::response::{IntoResponse, Response};
use irs_answers::timing;
use serde::Serialize;
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
/// `took_ms` (the milliseconds since `started`, to the microsecond) as its last field.
pub(crate) fn with_took_ms(open: &[u8], started: Instant) -> Response {
    let took_ms = timing::took_ms(started);
    let mut body = Vec::with_capacity(open.len() + 32);
    body.extend_from_slice(open);
    timing::close_with_took_ms(&mut body, took_ms);
    ([(header::CONTENT_TYPE, "application/json")], body).into_response()
}
