#![warn(missing_docs)]
//! What the CLI and the HTTP service of irs-planner share: each use case as one function both
//! front doors call, and the formats a result leaves the model in (phase text and codes, PNG
//! pictures, Nav2 masks, `.npy` values, export archives, `took_ms`).
//!
//! The model crate ([`irs_model`]) computes; this crate turns its results into what users
//! read, so the two front doors answer the same bytes. It holds no HTTP and no CLI.
//!
//! From a scenario to a path in a few lines:
//!
//! ```
//! use irs_model::phases::PhaseMode;
//! use irs_model::planner::{self, Threshold};
//! use irs_model::radiomap::{MapKey, Progress};
//! use irs_model::scenario::Scenario;
//! use irs_answers::scenario::ScenarioDocument;
//!
//! let floor = Scenario::builtin("paper-single-user").unwrap();
//! let key = MapKey::gain(&floor.content_hash(), &floor, PhaseMode::Continuous).unwrap();
//! let map = irs_answers::map::build(&floor, &key, &Progress::default()).unwrap();
//! let path = planner::plan(&map, map.native_unit(), Default::default(), [-10.0, 0.0], [10.0, 0.0], Threshold::Max, 1.0).unwrap();
//! assert!(path.feasible && path.max_feasible_threshold.unwrap() > -60.0);
//! ```

pub mod encoding;
pub mod export;
pub mod files;
pub mod fleet;
pub mod json;
pub mod map;
pub mod mapfile;
pub mod path;
pub mod path_json;
pub mod phase_text;
pub mod render;
pub mod route;
pub mod route_graph;
pub mod scenario;
pub mod timing;
pub mod vda5050;
