//! The HTTP layer: problem+json answers ([`problem`]) and authentication at the door
//! ([`auth`]). Handlers parse a request, call the application and render its answer; the
//! application's errors become problems only here.

pub(crate) mod auth;
pub(crate) mod json;
pub(crate) mod problem;
