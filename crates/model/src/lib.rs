#![warn(missing_docs)]
//! irs-planner: radio maps and communication-aware robot paths for an indoor floor served by an
//! access point and an intelligent reflecting surface (IRS), after "IRS Enhanced Indoor Robot
//! Path Planning: A Radio Map based Approach". The model the code implements is written down in
//! `docs/model.md`; doc comments cite its sections (§n) and the paper's equation numbers.
//!
//! The model takes validated values and returns values; documents (JSON, base64, ids) are the
//! answers crate's (`irs_answers`, whose crate documentation starts from a scenario document
//! and ends at a path).
//!
//! # Layout
//!
//! Data flows one way; each module uses only those above it in this list.
//!
//! * [`input`], [`numerics`], [`vecmath`]: the field error every rejection carries and the
//!   parsers the CLI and the API share; small numerical tools (ℓ₁ norm, golden section, Monte
//!   Carlo means); ln and exp over whole rows, vectorised.
//! * [`scenario`]: the scenario — validation (every error naming its field), grid.
//! * [`channel`]: geometry, blockage, path loss and the per-location (h̃, w̃, τ) of Lemma 1;
//!   [`phases`]: continuous, b-bit and no-IRS phase modes.
//! * [`rate`]: NOMA/OMA expected rates and the closed-form power split.
//! * [`solver`]: per-cell rate maximisation (`fast`, `sdr-sca`) and the SDR certificate.
//! * [`radiomap`]: map keys, gain maps, rate maps, their statistics and stored parts, and the
//!   cost estimates a service checks against its budgets before a build.
//! * [`planner`]: the feasible-map graph, shortest and widest paths, path and sweep answers.
//! * [`placement`]: where to mount an IRS or an AP, ranked by an objective.
//! * [`montecarlo`]: a Monte Carlo check of a path.
//!
//! The two front doors (`irs-service`, HTTP; the `irs-planner` binary's CLI) and the formats
//! they share (`irs-answers`) translate between users and these modules and hold no physics
//! (docs/architecture.md).

pub mod channel;
pub mod fleet;
pub mod floorplan;
pub mod geometry;
pub mod input;
pub mod montecarlo;
pub mod numerics;
pub mod outline;
pub mod phases;
pub mod placement;
pub mod planner;
pub mod radiomap;
pub mod rate;
pub mod scenario;
pub mod solver;
pub mod vecmath;
