//! The application: what the service does, independent of HTTP. Its errors ([`Error`]) carry
//! no status code (`http::problem` maps them), and identity ([`identity`]: tokens, owners,
//! callers) is decided here, not in the transport.

pub(crate) mod error;
pub(crate) mod identity;

pub(crate) use error::Error;
