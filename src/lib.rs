//! irs-planner: radio maps and communication-aware robot paths for an indoor floor served by one
//! access point and an intelligent reflecting surface (IRS), after "IRS Enhanced Indoor Robot
//! Path Planning: A Radio Map based Approach" (see SPEC.md and the README).
//!
//! Data flows one way: [`scenario`] → [`channel`] → [`radiomap`] (with [`rate`] and [`solver`]
//! for rate maps) → [`planner`] → the CLI ([`cli`]) and the HTTP [`service`]; [`render`] draws
//! maps and paths as PNG.

pub mod channel;
pub mod cli;
pub mod montecarlo;
pub mod planner;
pub mod radiomap;
pub mod rate;
pub mod render;
pub mod scenario;
pub mod service;
pub mod solver;
