//! What the CLI and the HTTP service of irs-planner share: the formats a radio map leaves the
//! model in (PNG pictures, Nav2 masks, `.npy` values, export archives).
//!
//! The model crate ([`irs_model`]) computes; this crate turns its results into what users
//! read, so the two front doors answer the same bytes.

pub mod export;
pub mod render;
