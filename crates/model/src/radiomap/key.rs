//! What defines a map: its [`MapKey`] (scenario id, kind, phase mode, access, solver), whose
//! hash (`irs_answers::map::map_id`) is the map id under which the map is cached and served.

use crate::input::{FieldError, parse_name};
use crate::phases::PhaseMode;
use crate::rate::Access;
use crate::scenario::Scenario;
use crate::solver::SolverKind;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Which value a map holds per cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapKind {
    /// Channel power gain map C (dB), docs/model.md §3.
    Gain,
    /// Communication rate map U of the MRU (bit/s/Hz), docs/model.md §4.
    Rate,
}

impl FromStr for MapKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        parse_name(s)
    }
}

impl fmt::Display for MapKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            MapKind::Gain => "gain",
            MapKind::Rate => "rate",
        })
    }
}

/// The version of the model's physics. Bumped by every change that alters a value of any
/// existing key's map, so that a map built before (kept in a data directory or Redis) is never
/// served for it: the map id hashes the key, and the key carries this version.
/// 2: a cell is occupied when an obstacle overlaps its square, not only its centre.
/// 3: with several APs, the one received strongest serves a cell, not the one of best gain.
/// 4: a rate map's value, power split and decoding order are those of its phases as stored
///    (16-bit codes), not of the unrounded ones.
/// 5: a link reaching less than 10⁻⁹ m into an obstacle grazes it (decimal coordinates rounded
///    into a face no longer block).
/// 6: rate maps with two or more SRUs carry the joint dual bound, and their `fast` values may
///    be higher where the certificate's rounded dual found a better decoding order.
/// 7: rate maps with two or more SRUs warm-start the `fast` search from the previous cell
///    where the certificate proves the answer (values the same within 10⁻⁹ or higher, bounds
///    the same within 10⁻⁹ or lower).
/// 8: the path gains' logarithm and exponential sum their polynomials by Estrin's scheme, not
///    Horner's (the same within 2 ulp of the correctly rounded result; gain maps within
///    10⁻¹³ dB of version 7's).
pub const MODEL_VERSION: u32 = 8;

/// Everything that defines a map; its hash is the map id.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapKey {
    /// The id of the scenario the map is of (a hash of its canonical document).
    pub scenario_id: String,
    /// Gain map (dB) or rate map (bit/s/Hz).
    pub kind: MapKind,
    /// How the IRS phases are chosen; `none` for a scenario without an IRS.
    pub phases: PhaseMode,
    /// Rate maps only (default `noma`).
    pub access: Option<Access>,
    /// Rate maps only (default `fast`).
    pub solver: Option<SolverKind>,
    /// The [`MODEL_VERSION`] the map is built with. Left out of the key's document at 1 (and
    /// read as 1 where absent), so ids from before versions existed are unchanged.
    #[serde(default = "first_version", skip_serializing_if = "is_first_version")]
    pub model_version: u32,
}

fn first_version() -> u32 {
    1
}

fn is_first_version(version: &u32) -> bool {
    *version == 1
}

impl MapKey {
    /// Normalises a request as users write it (every parameter but the kind optional): gain
    /// maps take no `access`/`solver`, rate maps default them to `noma`/`fast`, phases default
    /// to `continuous` (`none` for a scenario without an IRS), and the scenario must be able to
    /// support the kind. Errors name the request's field (`phases`, `access`, `solver`, `kind`).
    pub fn new(
        scenario_id: &str,
        scenario: &Scenario,
        kind: MapKind,
        phases: Option<PhaseMode>,
        access: Option<Access>,
        solver: Option<SolverKind>,
    ) -> Result<MapKey, FieldError> {
        let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
        // Without an IRS the only mode is `none`, so that is the default there.
        let has_irs = !scenario.surfaces().is_empty();
        let phases = phases.unwrap_or(if has_irs {
            PhaseMode::Continuous
        } else {
            PhaseMode::None
        });
        if !has_irs && phases != PhaseMode::None {
            return err(
                "phases",
                "the scenario has no IRS: send \"none\" (or leave phases out)",
            );
        }
        let (access, solver) = match kind {
            MapKind::Gain => {
                if access.is_some() {
                    return err("access", "applies only to rate maps");
                }
                if solver.is_some() {
                    return err("solver", "applies only to rate maps");
                }
                (None, None)
            }
            MapKind::Rate => {
                if scenario.access_points().len() > 1 {
                    // docs/model.md §4: the IRSs have one phase vector for all APs at once, so
                    // the MRU's choice of AP reconfigures the surfaces under the other APs'
                    // static robots and breaks their rate guarantees; the per-AP NOMA/OMA model
                    // does not capture that coupling.
                    return err(
                        "aps",
                        "rate maps take one access point: with several, the IRS phases chosen \
                         for the MRU's AP would also set the channels of the other APs' static \
                         robots, whose rates the map guarantees; build a gain map, or one rate \
                         map per AP",
                    );
                }
                if scenario.srus.is_empty() {
                    return err(
                        "kind",
                        "a rate map needs at least one static robot (srus is empty)",
                    );
                }
                let solver = solver.unwrap_or(SolverKind::Fast);
                if !solver.is_available() {
                    return err(
                        "solver",
                        "\"sdr-sca\" needs the `sdp` cargo feature (Clarabel with BLAS/LAPACK); this build has it off",
                    );
                }
                (Some(access.unwrap_or(Access::Noma)), Some(solver))
            }
        };
        Ok(MapKey {
            scenario_id: scenario_id.to_string(),
            kind,
            phases,
            access,
            solver,
            model_version: MODEL_VERSION,
        })
    }

    /// The key of a channel power gain map.
    pub fn gain(
        scenario_id: &str,
        scenario: &Scenario,
        phases: PhaseMode,
    ) -> Result<MapKey, FieldError> {
        MapKey::new(
            scenario_id,
            scenario,
            MapKind::Gain,
            Some(phases),
            None,
            None,
        )
    }

    /// The key of a rate map solved by the default (`fast`) solver.
    pub fn rate(
        scenario_id: &str,
        scenario: &Scenario,
        phases: PhaseMode,
        access: Access,
    ) -> Result<MapKey, FieldError> {
        MapKey::new(
            scenario_id,
            scenario,
            MapKind::Rate,
            Some(phases),
            Some(access),
            None,
        )
    }

    /// The unit of the map's values.
    pub fn unit(&self) -> &'static str {
        super::Unit::native(self.kind).symbol()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_reject_what_does_not_apply() {
        let s = Scenario::builtin("small-test").unwrap();
        let e = MapKey::new("x", &s, MapKind::Gain, None, Some(Access::Oma), None).unwrap_err();
        assert_eq!(e.field, "access");
        let rate = MapKey::new("x", &s, MapKind::Rate, None, None, None).unwrap();
        assert_eq!(
            (rate.access, rate.solver),
            (Some(Access::Noma), Some(SolverKind::Fast))
        );
        assert_eq!(
            rate,
            MapKey::rate("x", &s, PhaseMode::Continuous, Access::Noma).unwrap()
        );
        assert_eq!("rate".parse::<MapKind>(), Ok(MapKind::Rate));
        assert_eq!(MapKind::Gain.to_string(), "gain");
    }

    #[test]
    fn scenarios_without_an_irs_default_to_no_phases() {
        let s = Scenario::builtin("small-test")
            .unwrap()
            .with_surfaces(Vec::new())
            .unwrap();
        let key = MapKey::new("x", &s, MapKind::Gain, None, None, None).unwrap();
        assert_eq!(key.phases, PhaseMode::None);
        let e = MapKey::gain("x", &s, PhaseMode::Continuous).unwrap_err();
        assert_eq!(e.field, "phases");
        assert!(e.reason.contains("\"none\""), "{e}");
    }

    #[test]
    fn sdr_sca_without_the_sdp_feature_is_a_clear_error() {
        let s = Scenario::builtin("small-test").unwrap();
        let key = MapKey::new("x", &s, MapKind::Rate, None, None, Some(SolverKind::SdrSca));
        if SolverKind::SdrSca.is_available() {
            assert_eq!(key.unwrap().solver, Some(SolverKind::SdrSca));
        } else {
            let e = key.unwrap_err();
            assert_eq!(e.field, "solver");
            assert!(e.reason.contains("sdp"), "{e}");
        }
    }
}
