//! The HTTP planning service: axum on tokio, maps cached in moka, builds on a bounded blocking
//! pool, `tracing` spans per request and per job, Prometheus metrics. The contract is
//! `openapi.yaml`.
//!
//! Layout: [`config`] (flags and environment), [`http`] (the route table, one module of
//! handlers per resource, the middleware stack, problem+json answers with [`Problem`] the body
//! of every error answer, authentication at the door), `app` (the application's own error type and
//! identity: tokens, owners, callers), `cache` (scenario registry, map cache and the maps'
//! widest-path indexes), `answers` (path answers kept for repeated queries), `jobs` (map builds
//! and placement searches), `queries` (admission of heavy queries), [`runtime`] (`run`: one
//! server on a listener, with its own metrics registry; `serve`: the process's entry; the
//! accept loop and its timeouts), `store` (the data directory of `--data-dir`), `cluster` (replicas sharing
//! Redis, `--redis-url`), `viewer` (the built-in map viewer at `/`).

pub(crate) mod answers;

pub mod app;
pub(crate) mod cache;
pub(crate) mod cluster;
pub mod config;
pub mod http;
pub(crate) mod jobs;
pub(crate) mod priority;
pub mod probe;
pub(crate) mod queries;
pub mod runtime;
pub(crate) mod store;
pub(crate) mod viewer;

pub use app::App;
pub use http::problem::Problem;
pub use runtime::{ServeError, run, serve};
