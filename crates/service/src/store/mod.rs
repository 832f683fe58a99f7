//! Storage below the application: the data directory of one node ([`disk`], `--data-dir`)
//! and the store replicas share ([`redis`], `--redis-url`). Neither knows HTTP or the
//! application's rules; their refusals are [`Error`]s, which the application maps to its own.

pub(crate) mod disk;
pub(crate) mod redis;

pub(crate) use disk::{DataDir, Kind};

/// Why the shared store refused.
#[derive(Debug, Clone, thiserror::Error)]
pub(crate) enum Error {
    /// It cannot be used now (down, timing out, or a lock that kept changing hands).
    #[error("{reason}")]
    Unavailable { reason: String },
    /// `limit` builds are already queued or running in the whole cluster.
    #[error("{limit} builds are already queued or running")]
    Full { limit: usize },
}

impl Error {
    pub fn unavailable(reason: impl Into<String>) -> Self {
        Error::Unavailable {
            reason: reason.into(),
        }
    }
}
