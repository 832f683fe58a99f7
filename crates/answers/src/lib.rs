//! What the CLI and the HTTP service of irs-planner share: each use case as one function both
//! front doors call, and the formats a result leaves the model in (phase text and codes, PNG
//! pictures, Nav2 masks, `.npy` values, export archives, `took_ms`).
//!
//! The model crate ([`irs_model`]) computes; this crate turns its results into what users
//! read, so the two front doors answer the same bytes. It holds no HTTP and no CLI.

pub mod export;
pub mod map;
pub mod path;
pub mod phase_text;
pub mod render;
pub mod timing;
