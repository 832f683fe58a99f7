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
//!   are, jobs, identity, the cluster's build loop) and its error type; with what it runs on:
//!   `cache` (scenario registry, map cache and the maps' widest-path indexes), `answers` (path
//!   answers kept for repeated queries), `jobs` (map builds and placement searches), `queries`
//!   (admission of heavy queries);
//! * `store`: the data directory of `--data-dir` and the Redis store of `--redis-url`;
//! * leaves: [`config`] (flags and environment), `tasks` (spawning with the server's metrics
//!   registry), `priority`, [`probe`], `viewer` (the built-in map viewer at `/`).

pub(crate) mod answers;

pub mod app;
pub(crate) mod cache;
pub mod config;
pub mod http;
pub(crate) mod ids;
pub(crate) mod jobs;
pub(crate) mod priority;
pub mod probe;
pub(crate) mod queries;
pub mod runtime;
pub(crate) mod store;
pub(crate) mod tasks;
pub(crate) mod viewer;

pub use app::App;
pub use http::problem::Problem;
pub use runtime::{ServeError, run, serve};
