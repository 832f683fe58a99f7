//! The service's identifiers and the links built from them. Each id is a string on the wire,
//! in the data directory and in Redis (`serde(transparent)`), so these types change no byte
//! there; they keep a map id from being passed where a job id is meant, and every `href` the
//! API answers is built here.

use irs_answers::scenario::ScenarioDocument as _;
use irs_model::radiomap::{MapKey, RadioMap};
use irs_model::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::fmt;

/// Declares a string id: transparent to serde, shown as its text.
macro_rules! string_id {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Debug, Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
        #[serde(transparent)]
        pub struct $name(String);

        impl $name {
            /// The id as a client, a file name or a stored record gave it (unchecked: an id
            /// that names nothing is simply not found).
            pub fn given(id: impl Into<String>) -> Self {
                $name(id.into())
            }

            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        /// Lookups and joins by the text (hashes and compares as the `String` it holds).
        impl std::borrow::Borrow<str> for $name {
            fn borrow(&self) -> &str {
                &self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }
    };
}

string_id!(
    /// A map's id: the hash of its key ([`irs_answers::map::map_id`]).
    MapId
);
string_id!(
    /// A scenario's id: the hash of its canonical document.
    ScenarioId
);
string_id!(
    /// A job's id (a placement's id is its job's): a random UUID.
    JobId
);

impl MapId {
    /// The id of the map `key` defines.
    pub fn of(key: &MapKey) -> Self {
        MapId(irs_answers::map::map_id(key))
    }

    /// The id a built map carries.
    pub fn of_map(map: &RadioMap) -> Self {
        MapId(map.id.clone())
    }

    pub fn href(&self) -> String {
        format!("/v1/maps/{self}")
    }
}

impl ScenarioId {
    /// The id of a scenario: the hash of its canonical document.
    pub fn of(scenario: &Scenario) -> Self {
        ScenarioId(scenario.content_hash())
    }

    /// The id of the scenario whose canonical document is `canonical` (when the caller needs
    /// the document itself too: a floor plan's is megabytes, made once).
    pub fn of_canonical(canonical: &str) -> Self {
        ScenarioId(irs_answers::scenario::hash_hex(canonical.as_bytes()))
    }

    /// The scenario a map key is of.
    pub fn of_key(key: &MapKey) -> Self {
        ScenarioId(key.scenario_id.clone())
    }

    pub fn href(&self) -> String {
        format!("/v1/scenarios/{self}")
    }
}

impl JobId {
    /// A new job's id.
    pub fn random() -> Self {
        JobId(uuid::Uuid::new_v4().simple().to_string())
    }

    pub fn href(&self) -> String {
        format!("/v1/jobs/{self}")
    }

    /// Where a placement job's answer is read.
    pub fn placement_href(&self) -> String {
        format!("/v1/placements/{self}")
    }
}
