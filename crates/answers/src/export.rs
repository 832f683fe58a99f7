//! A built map in the formats a robot stack reads (docs/scenarios.md "Exports"):
//!
//! * a Nav2 **keep-out mask** at a threshold γ: one pixel per grid cell, occupied (100) where
//!   the cell is occupied or its value is below γ, free (0) elsewhere — a `trinary` PGM + YAML
//!   with the grid's resolution and origin, for Nav2's keepout filter;
//! * a Nav2 **cost mask** (speed-filter style): occupied or below γ → 100; otherwise
//!   `round(99 · clamp((best − v)/(best − γ), 0, 1))`, so the threshold maps to 99, `best` (by
//!   default the map's maximum) and above to 0, monotone in between — a `scale` PGM + YAML;
//! * the raw values as a NumPy `.npy` (float32, C order, shape (nx, ny): `a[i, j]` is the cell
//!   centred at (x_min + iΔ, y_min + jΔ), NaN where occupied or infeasible).
//!
//! Mask pixels are centred on cell centres: the mask's origin is (x_min − Δ/2, y_min − Δ/2).
//! Importing a keep-out mask as a floor plan of the same room and resolution marks exactly the
//! mask's cells occupied (tested).

use crate::mapfile::{self, EncodedMap};
use irs_model::floorplan::MapMode;
use irs_model::input::FieldError;
use irs_model::radiomap::{RadioMap, Unit};

/// Which Nav2 mask.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MaskKind {
    /// Keep-out: occupied or below γ → 100, else 0 (`trinary`, for Nav2's keepout filter).
    #[default]
    Keepout,
    /// Cost: occupied or below γ → 100, else 99 at γ down to 0 at `best` (`scale`, speed-filter
    /// style).
    Cost,
}

impl std::str::FromStr for MaskKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        irs_model::input::parse_name(s)
    }
}

impl MaskKind {
    /// The files' stem inside an archive or a directory.
    pub fn stem(self) -> &'static str {
        match self {
            MaskKind::Keepout => "keepout",
            MaskKind::Cost => "cost",
        }
    }
}

/// A mask as files: `{stem}.yaml` naming `{stem}.pgm`.
#[derive(Debug, Clone, PartialEq)]
pub struct Nav2Mask {
    /// Which mask; names its files.
    pub kind: MaskKind,
    /// The YAML and the PGM it names.
    pub files: EncodedMap,
    /// When the map was built (seconds since the Unix epoch): the files' date in an archive.
    pub built_at_unix_s: u64,
}

impl Nav2Mask {
    /// `keepout.yaml` or `cost.yaml`.
    pub fn yaml_name(&self) -> String {
        format!("{}.yaml", self.kind.stem())
    }
    /// `keepout.pgm` or `cost.pgm`, the image the YAML names.
    pub fn pgm_name(&self) -> String {
        format!("{}.pgm", self.kind.stem())
    }

    /// Both files in one tar archive, mode 0644 and dated when the map was built, so the bytes
    /// depend on the map only (the same on every replica, before and after a restart).
    pub fn tar(&self) -> Vec<u8> {
        let mut builder = tar::Builder::new(Vec::new());
        for (name, data) in [
            (self.yaml_name(), self.files.yaml.as_bytes()),
            (self.pgm_name(), self.files.pgm.as_slice()),
        ] {
            let mut header = tar::Header::new_gnu();
            header.set_size(data.len() as u64);
            header.set_mode(0o644);
            header.set_mtime(self.built_at_unix_s);
            builder
                .append_data(&mut header, name, data)
                .expect("writing into memory cannot fail");
        }
        builder
            .into_inner()
            .expect("writing into memory cannot fail")
    }
}

/// Nav2 cell values of a mask, row-major from the bottom row (pixel (c, r) = cell (i = c, j = r)).
fn mask_values(map: &RadioMap, values: &[f64], mut value_of: impl FnMut(f64) -> i8) -> Vec<i8> {
    let (nx, ny) = (map.grid.nx, map.grid.ny);
    let mut out = vec![100i8; nx * ny];
    for j in 0..ny {
        for i in 0..nx {
            let k = map.grid.index(i, j);
            if !map.occupied[k] {
                out[j * nx + i] = value_of(values[k]);
            }
        }
    }
    out
}

/// The mask of `kind` at `threshold` in `unit`. `best` (cost masks only, in `unit`) is the
/// value that costs 0; default the map's maximum. Errors name the query field.
pub fn nav2_mask(
    map: &RadioMap,
    unit: Unit,
    kind: MaskKind,
    threshold: f64,
    best: Option<f64>,
) -> Result<Nav2Mask, FieldError> {
    if !threshold.is_finite() {
        return Err(FieldError::new("threshold", "must be a finite number"));
    }
    let in_unit = map.values_in(unit)?;
    let values = match kind {
        MaskKind::Keepout => {
            if best.is_some() {
                return Err(FieldError::new("best", "applies only to cost masks"));
            }
            // NaN (infeasible) compares false, so it stays occupied.
            mask_values(map, &in_unit, |v| if v >= threshold { 0 } else { 100 })
        }
        MaskKind::Cost => {
            let best = match best {
                Some(b) => b,
                None => in_unit
                    .iter()
                    .copied()
                    .filter(|v| v.is_finite())
                    .fold(f64::NAN, f64::max),
            };
            if best.is_nan() || best <= threshold {
                return Err(FieldError::new(
                    "best",
                    format!(
                        "the value that costs 0 must exceed the threshold {threshold} (it is {best}; \
                         by default the map's maximum)"
                    ),
                ));
            }
            mask_values(map, &in_unit, |v| {
                if v >= threshold {
                    (99.0 * ((best - v) / (best - threshold)).clamp(0.0, 1.0)).round() as i8
                } else {
                    100
                }
            })
        }
    };
    let g = &map.grid;
    let half = g.resolution_m / 2.0;
    let mode = match kind {
        MaskKind::Keepout => MapMode::Trinary,
        MaskKind::Cost => MapMode::Scale,
    };
    let files = mapfile::encode_map(
        &values,
        g.nx,
        g.resolution_m,
        [g.x_min - half, g.y_min - half],
        mode,
        &format!("{}.pgm", kind.stem()),
    );
    Ok(Nav2Mask {
        kind,
        files,
        built_at_unix_s: map.built_at_unix_s,
    })
}

/// The map's values in `unit` as a NumPy `.npy` file: float32, shape (nx, ny), `a[i, j]` the
/// cell at (x_min + iΔ, y_min + jΔ) (the flat layout of [`RadioMap::values`]), NaN where
/// occupied. An error names `unit` when the map cannot be read in it.
pub fn npy(map: &RadioMap, unit: Unit) -> Result<Vec<u8>, FieldError> {
    use npyz::WriterBuilder;
    let values = map.values_in(unit)?;
    let mut out = Vec::with_capacity(values.len() * 4 + 128);
    let mut writer = npyz::WriteOptions::new()
        .default_dtype()
        .shape(&[map.grid.nx as u64, map.grid.ny as u64])
        .writer(&mut out)
        .begin_nd()
        .expect("writing into memory cannot fail");
    writer
        .extend(values.iter().map(|&v| v as f32))
        .expect("writing into memory cannot fail");
    writer.finish().expect("writing into memory cannot fail");
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::map::build;
    use crate::scenario::ScenarioDocument;
    use base64::Engine;
    use irs_model::phases::PhaseMode;
    use irs_model::radiomap::{MapKey, Progress};
    use irs_model::scenario::Scenario;

    fn small_map() -> (Scenario, RadioMap) {
        let s = Scenario::builtin("small-test").unwrap();
        let key = MapKey::gain("t", &s, PhaseMode::Continuous).unwrap();
        let map = build(&s, &key, &Progress::default()).unwrap();
        (s, map)
    }

    /// Importing the keep-out mask as the floor plan of the same room gives back exactly the
    /// mask: the cells below γ and the occupied cells are the new map's occupied cells.
    #[test]
    fn a_keepout_mask_imported_as_a_floor_plan_gives_back_the_mask() {
        let (s, map) = small_map();
        let finite: Vec<f64> = map
            .values
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        let threshold = finite.iter().sum::<f64>() / finite.len() as f64;
        let mask = nav2_mask(&map, Unit::GainDb, MaskKind::Keepout, threshold, None).unwrap();
        let yaml: serde_json::Value = serde_saphyr::from_str(&mask.files.yaml).unwrap();
        let mut document = s.to_json_value();
        document["obstacles"] = serde_json::json!([]);
        document["floor_plan"] = serde_json::json!({
            "image": base64::engine::general_purpose::STANDARD.encode(&mask.files.pgm),
            "resolution": yaml["resolution"], "origin": yaml["origin"], "negate": yaml["negate"],
            "occupied_thresh": yaml["occupied_thresh"], "free_thresh": yaml["free_thresh"],
            "mode": yaml["mode"],
            // A mask says where to drive, not what blocks radio: keep it below the SRUs.
            "obstacle_height_m": 0.01,
        });
        let imported = Scenario::from_value(document).unwrap();
        let key = MapKey::gain("u", &imported, PhaseMode::Continuous).unwrap();
        let again = build(&imported, &key, &Progress::default()).unwrap();
        let expected: Vec<bool> = (0..map.grid.cells())
            .map(|k| map.occupied[k] || map.values[k].is_nan() || map.values[k] < threshold)
            .collect();
        assert!(expected.iter().any(|&o| o) && expected.iter().any(|&o| !o));
        assert_eq!(again.occupied, expected);
    }

    #[test]
    fn cost_masks_are_monotone_and_span_the_range() {
        let (_, map) = small_map();
        let threshold = -70.0;
        let mask = nav2_mask(&map, Unit::GainDb, MaskKind::Cost, threshold, None).unwrap();
        let plan = irs_model::floorplan::FloorPlan {
            image: "".into(),
            resolution: map.grid.resolution_m,
            origin: [0.0; 3],
            negate: irs_model::floorplan::Negate(false),
            occupied_thresh: 1.0,
            free_thresh: 0.0,
            mode: MapMode::Scale,
            unknown_as: irs_model::floorplan::UnknownAs::Occupied,
            map_io: Default::default(),
            obstacle_height_m: None,
        };
        // Decode the PGM's pixels as Nav2 would (image row 0 is the top: cell row ny − 1).
        let body_start = mask.files.pgm.len() - map.grid.cells();
        let pixels = &mask.files.pgm[body_start..];
        let (nx, ny) = (map.grid.nx, map.grid.ny);
        let mut pairs = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let cost = irs_model::floorplan::nav2_value(pixels[(ny - 1 - j) * nx + i], &plan);
                pairs.push((map.values[map.grid.index(i, j)], cost));
            }
        }
        let mut free: Vec<(f64, i8)> = pairs
            .iter()
            .copied()
            .filter(|(v, _)| v.is_finite())
            .collect();
        free.sort_by(|a, b| a.0.total_cmp(&b.0));
        assert!(
            free.windows(2).all(|w| w[0].1 >= w[1].1),
            "cost falls as the value rises"
        );
        assert_eq!(free.last().unwrap().1, 0, "the best cell costs 0");
        assert!(
            pairs
                .iter()
                .filter(|(v, _)| v.is_nan())
                .all(|(_, c)| *c == 100)
        );
        assert!(free.iter().all(|(v, c)| (*v < threshold) == (*c == 100)));
        let e = nav2_mask(
            &map,
            Unit::GainDb,
            MaskKind::Cost,
            threshold,
            Some(threshold - 1.0),
        )
        .unwrap_err();
        assert_eq!(e.field, "best");
    }

    #[test]
    fn the_archive_holds_both_files() {
        let (_, map) = small_map();
        let mask = nav2_mask(&map, Unit::GainDb, MaskKind::Keepout, -70.0, None).unwrap();
        let bytes = mask.tar();
        let mut archive = tar::Archive::new(bytes.as_slice());
        let entries: Vec<(String, u64)> = archive
            .entries()
            .unwrap()
            .map(|e| {
                let e = e.unwrap();
                (
                    e.path().unwrap().display().to_string(),
                    e.header().mtime().unwrap(),
                )
            })
            .collect();
        let built = map.built_at_unix_s;
        // Dated when the map was built: after this file was written, not 1970.
        assert!(built > 1_780_000_000, "{built}");
        assert_eq!(
            entries,
            [
                ("keepout.yaml".into(), built),
                ("keepout.pgm".into(), built)
            ]
        );
        assert!(mask.files.yaml.contains("image: keepout.pgm"));
    }

    #[test]
    fn npy_holds_the_values_in_c_order() {
        let (_, map) = small_map();
        let bytes = npy(&map, Unit::GainDb).unwrap();
        let file = npyz::NpyFile::new(bytes.as_slice()).unwrap();
        assert_eq!(file.shape(), [map.grid.nx as u64, map.grid.ny as u64]);
        let read: Vec<f32> = file.into_vec().unwrap();
        for (a, b) in read.iter().zip(&map.values) {
            assert!(a.is_nan() && b.is_nan() || *a == *b as f32);
        }
    }
}
