//! A compact binary form of a built map, for storage (`serve --data-dir`): what the build
//! computed, without what the scenario determines.
//!
//! Stored: the map key (as JSON), the build's duration and end, and per cell the value (f64), the occupancy
//! (one byte) and the per-cell solution (gain maps: the serving AP, one byte, only with several
//! APs, and its gain where another AP has the best one; rate maps: the upper bound, N phase codes (`u16`, as the map holds them), the power split
//! and the decoding order). Not stored: the grid, the channel models and the rate model, which
//! [`decode`] rebuilds from the scenario (they are deterministic functions of it). The bytes are postcard (serde's compact
//! format); f64 values keep their bits, so a decoded map is bit-identical to the one encoded,
//! NaN cells included. The paper's 41² gain map is 15 kB; a 1001² one about 9 MB.
//!
//! The encoding carries no checksum of its own: the store frames it with a digest
//! (the service's store), and [`decode`] checks every length against the scenario's grid, so
//! bytes that parse but belong to another scenario are refused.

use crate::map::map_id;
use crate::scenario::ScenarioDocument;
use irs_model::radiomap::{MapKey, RadioMap, RateRow, StoredCells};
use irs_model::scenario::Scenario;
use serde::{Deserialize, Serialize};

/// Bumped whenever the layout below changes; a stored map of another version is not decoded
/// (it is rebuilt on request).
pub const FORMAT_VERSION: u32 = 4;

#[derive(Serialize, Deserialize)]
struct Stored {
    version: u32,
    /// The key as JSON: its types (the phase mode) deserialise from JSON's self-describing
    /// forms, which postcard does not carry.
    key: String,
    build_seconds: f64,
    built_at_unix_s: u64,
    values: Vec<f64>,
    occupied: Vec<bool>,
    cells: StoredCells,
}

/// Why stored bytes are not a map of the given scenario.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The bytes do not parse as a stored map (truncated, another layout, or a bad key).
    #[error("not a stored map: {0}")]
    Malformed(String),
    /// Stored in another [`FORMAT_VERSION`]: the map is rebuilt rather than decoded.
    #[error("stored in format version {found}, this build reads version {FORMAT_VERSION}")]
    Version {
        /// The format version the bytes were written in.
        found: u32,
    },
    /// A well-formed map of another scenario, or whose lengths do not fit this scenario's grid.
    #[error("{0}")]
    Mismatch(String),
}

/// The map's bytes.
pub fn encode(map: &RadioMap) -> Vec<u8> {
    let stored = Stored {
        version: FORMAT_VERSION,
        key: serde_json::to_string(&map.key).expect("keys serialise"),
        build_seconds: map.build_seconds,
        built_at_unix_s: map.built_at_unix_s,
        values: map.values.clone(),
        occupied: map.occupied.clone(),
        cells: map.stored_cells(),
    };
    postcard::to_stdvec(&stored).expect("a map serialises to memory")
}

/// The key of the map that `bytes` encode, from their first bytes only (a prefix of a few
/// hundred bytes is enough).
pub fn peek_key(bytes: &[u8]) -> Result<MapKey, DecodeError> {
    let (found, rest) = postcard::take_from_bytes::<u32>(bytes)
        .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    if found != FORMAT_VERSION {
        return Err(DecodeError::Version { found });
    }
    let (key, _) = postcard::take_from_bytes::<&str>(rest)
        .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    parse_key(key)
}

fn parse_key(json: &str) -> Result<MapKey, DecodeError> {
    serde_json::from_str(json).map_err(|e| DecodeError::Malformed(format!("the map key: {e}")))
}

/// The map that `bytes` encode, given the scenario it was built from (its id must be the
/// key's `scenario_id`).
pub fn decode(bytes: &[u8], scenario: &Scenario) -> Result<RadioMap, DecodeError> {
    // The version comes first, so a future layout is reported as such, not as garbage.
    let (found, _) = postcard::take_from_bytes::<u32>(bytes)
        .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    if found != FORMAT_VERSION {
        return Err(DecodeError::Version { found });
    }
    let stored: Stored =
        postcard::from_bytes(bytes).map_err(|e| DecodeError::Malformed(e.to_string()))?;
    let key = parse_key(&stored.key)?;
    if key.scenario_id != scenario.content_hash() {
        return Err(DecodeError::Mismatch(format!(
            "built from scenario {}, not {}",
            key.scenario_id,
            scenario.content_hash()
        )));
    }
    let id = map_id(&key);
    RadioMap::from_parts(
        scenario,
        key,
        id,
        stored.build_seconds,
        stored.built_at_unix_s,
        stored.values,
        stored.occupied,
        stored.cells,
    )
    .map_err(DecodeError::Mismatch)
}

/// A batch of solved rate-map rows, as a build's checkpoint stores them: postcard after the
/// [`FORMAT_VERSION`]. The rows belong to the map whose id the store keys them by (which
/// names the model version), and the build that resumes from them checks their lengths.
pub fn encode_rows(rows: &[RateRow]) -> Vec<u8> {
    postcard::to_stdvec(&(FORMAT_VERSION, rows)).expect("rows serialise to memory")
}

/// The rows of a batch [`encode_rows`] wrote.
pub fn decode_rows(bytes: &[u8]) -> Result<Vec<RateRow>, DecodeError> {
    let (found, rest) = postcard::take_from_bytes::<u32>(bytes)
        .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    if found != FORMAT_VERSION {
        return Err(DecodeError::Version { found });
    }
    postcard::from_bytes(rest).map_err(|e| DecodeError::Malformed(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::build;
    use irs_model::radiomap::{MapKind, Progress};

    fn builtin(name: &str) -> Scenario {
        Scenario::builtin(name).expect("a built-in scenario")
    }

    /// The small test floor and the key of its rate map.
    fn small_rate_map() -> (Scenario, MapKey) {
        let small = builtin("small-test");
        let key = MapKey::new(
            &small.content_hash(),
            &small,
            MapKind::Rate,
            None,
            None,
            None,
        );
        (small, key.unwrap())
    }

    fn round_trip(scenario: &Scenario, key: &MapKey) {
        let map = build(scenario, key, &Progress::default()).expect("builds");
        let bytes = encode(&map);
        let back = decode(&bytes, scenario).expect("decodes");
        assert_eq!(back.key, map.key);
        assert_eq!(back.build_seconds.to_bits(), map.build_seconds.to_bits());
        assert_eq!(back.built_at_unix_s, map.built_at_unix_s);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.values), bits(&map.values));
        assert_eq!(back.occupied, map.occupied);
        // Every waypoint configuration, the part a path answer returns, is the same.
        for index in 0..map.values.len() {
            assert_eq!(
                back.cell_config(index),
                map.cell_config(index),
                "cell {index}"
            );
        }
        assert_eq!(back.stats(), map.stats());
        assert_eq!(back.certificate_summary(), map.certificate_summary());
        // At most the bytes held in memory, minus the channel models.
        assert!(
            bytes.len() <= map.size_bytes() + 64,
            "{} bytes",
            bytes.len()
        );
    }

    /// A checkpoint's rows come back bit for bit (NaN cells included); other bytes are refused.
    #[test]
    fn checkpoint_rows_round_trip_and_other_bytes_are_refused() {
        let (small, key) = small_rate_map();
        let checkpoint = irs_model::radiomap::Checkpoint::recording(Vec::new());
        crate::map::build_resuming(&small, &key, &Progress::default(), &checkpoint).unwrap();
        let rows = checkpoint.take_solved();
        assert!(rows.iter().any(|r| r.values.iter().any(|v| v.is_nan())));
        let bytes = encode_rows(&rows);
        let back = decode_rows(&bytes).unwrap();
        let bits = |rows: &[RateRow]| -> Vec<Vec<u64>> {
            rows.iter()
                .map(|r| {
                    r.values
                        .iter()
                        .chain(&r.upper_bound)
                        .chain(&r.power_w)
                        .map(|v| v.to_bits())
                        .collect()
                })
                .collect()
        };
        assert_eq!(bits(&back), bits(&rows));
        assert!(
            back.iter()
                .zip(&rows)
                .all(|(a, b)| (a.row, &a.phases, &a.order) == (b.row, &b.phases, &b.order))
        );
        assert!(matches!(
            decode_rows(&bytes[..bytes.len() - 1]),
            Err(DecodeError::Malformed(_))
        ));
        let mut other = bytes.clone();
        other[0] = 99;
        assert_eq!(decode_rows(&other), Err(DecodeError::Version { found: 99 }));
    }

    #[test]
    fn gain_and_rate_maps_round_trip_bit_for_bit() {
        let small = builtin("small-test");
        let id = small.content_hash();
        for kind in [MapKind::Gain, MapKind::Rate] {
            let key = MapKey::new(&id, &small, kind, None, None, None).unwrap();
            round_trip(&small, &key);
        }
        // Two APs: the gain map stores which one serves each cell.
        let paper = builtin("paper-single-user");
        let mut second = paper.ap().clone();
        second.position = [9.5, -9.5, 2.0];
        let multi = paper
            .with_access_points(vec![paper.ap().clone(), second])
            .unwrap();
        let key = MapKey::new(
            &multi.content_hash(),
            &multi,
            MapKind::Gain,
            None,
            None,
            None,
        )
        .unwrap();
        round_trip(&multi, &key);
    }

    #[test]
    fn bytes_of_another_scenario_or_damaged_bytes_are_refused() {
        let (small, key) = small_rate_map();
        let bytes = encode(&build(&small, &key, &Progress::default()).unwrap());
        let other = builtin("paper-single-user");
        assert!(matches!(
            decode(&bytes, &other),
            Err(DecodeError::Mismatch(_))
        ));
        assert!(matches!(
            decode(&bytes[..bytes.len() / 2], &small),
            Err(DecodeError::Malformed(_))
        ));
        let mut future = bytes.clone();
        future[0] = 9;
        assert_eq!(
            decode(&future, &small).unwrap_err(),
            DecodeError::Version { found: 9 }
        );
    }
}
