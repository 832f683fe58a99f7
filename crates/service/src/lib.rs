#![warn(missing_docs)]
//! The HTTP planning service: axum on tokio, maps cached in moka, builds on a bounded blocking
//! pool, `tracing` spans per request and per job, Prometheus metrics. The contract is
//! `openapi.yaml`.
//!
//! Layers, each using only those below it:
//! * [`runtime`]: `run` (one server on a listener until a shutdown future resolves, with its
//!   own metrics registry, nothing process-wide) and `serve` (the process's entry), and the
//!   accept loop with its timeouts;
//! * [`http`]: the route table, one module of handlers per resource, the middleware stack,
//!   problem+json answers ([`Problem`] is the body of every error answer) and authentication at
//!   the door;
//! * [`app`]: the facade [`App`] the handlers call (scenario and map acquisition wherever they
//!   are, jobs, identity, the cluster's build loop) and its error type; and what it owns:
//!   `registry` (the scenarios), `cache` (maps and their widest-path indexes), `answers` (path
//!   answers kept for repeated queries), `jobs` (map builds and placement searches, their view
//!   and record), `queries` (admission of heavy queries);
//! * `store`: the state a deployment's nodes share, one trait with three implementations
//!   (memory, the data directory of `--data-dir`, the Redis store of `--redis-url`), which keep
//!   the application's records without knowing their types;
//! * leaves: [`config`] (flags and environment), `ids` (map, scenario and job ids and the
//!   links built from them), `tasks` (spawning with the server's metrics registry),
//!   `priority`, `memory` (large blocks handed back when freed), [`probe`], `viewer` (the
//!   built-in map viewer at `/`).

pub mod app;
pub mod config;
pub mod http;
pub(crate) mod ids;
pub(crate) mod memory;
pub(crate) mod priority;
pub mod probe;
pub mod runtime;
pub(crate) mod store;
pub(crate) mod tasks;
pub(crate) mod viewer;

pub use app::App;
pub use http::problem::Problem;
pub use runtime::{ServeError, run, serve};
