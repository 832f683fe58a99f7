//! ROS map files (`map.yaml` + its PGM/PNG image, the format of Nav2's map_server and of SLAM
//! tools) in and out of scenario documents (docs/scenarios.md "Floor plans"):
//!
//! * In: in a scenario file, `"floor_plan": {"map": "warehouse.yaml", …}` names a map YAML
//!   relative to the scenario file, its `image:` relative to the YAML (as Nav2 resolves it);
//!   [`resolve_map_reference`] turns that into the inline form (the fields and the image in
//!   base64), so a scenario id hashes the pixels and the fields, never a file name. The pixels
//!   themselves are read by the model (`irs_model::floorplan`).
//! * Out: [`encode_map`] writes a grid of Nav2 cell values as a PGM and its YAML, so that Nav2
//!   (and the model's decoder) read back exactly those values.

use crate::files;
use base64::Engine;
use irs_model::floorplan::{MapMode, Negate};
use irs_model::input::FieldError;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The map YAML as Nav2 reads it: `image`, `resolution`, `origin`, `negate`, `occupied_thresh`
/// and `free_thresh` required, `mode` optional (trinary); other keys are ignored, as Nav2 does.
#[derive(Debug, Deserialize, Serialize)]
struct MapYaml {
    image: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    mode: Option<MapMode>,
    resolution: f64,
    /// Written `[x, y, yaw]` on one line, as map_server writes it.
    origin: serde_saphyr::FlowSeq<Vec<f64>>,
    negate: Negate,
    occupied_thresh: f64,
    free_thresh: f64,
}

/// Rejects a file reference left in a document that was not read from a file (an HTTP body):
/// the server reads no files on a client's behalf.
pub fn reject_map_reference(document: &serde_json::Value) -> Result<(), FieldError> {
    match document.get("floor_plan").and_then(|p| p.get("map")) {
        Some(_) => Err(FieldError::new(
            "floor_plan.map",
            "a map file is read only where files are: in a scenario file given to the CLI or \
             found by `serve` at start-up; over HTTP send the map's fields and its image inline \
             (`irs-planner scenario --scenario FILE` prints that form)",
        )),
        None => Ok(()),
    }
}

/// Reads a file for [`resolve_map_reference`], refusing one of more than the given number of
/// bytes ([`crate::files::read_regular`] for files on disk).
pub type ReadFile<'a> = &'a dyn Fn(&Path, u64) -> std::io::Result<Vec<u8>>;

/// Replaces a file reference `floor_plan.map` in a scenario document by the map's fields and
/// image, read with `read`: the map YAML relative to `base` (the scenario file's folder), its
/// image relative to the YAML. A document without a reference is left as it is.
pub fn resolve_map_reference(
    document: &mut serde_json::Value,
    base: &Path,
    read: ReadFile,
) -> Result<(), FieldError> {
    let Some(plan) = document
        .get_mut("floor_plan")
        .and_then(|p| p.as_object_mut())
    else {
        return Ok(());
    };
    let Some(reference) = plan.get("map") else {
        return Ok(());
    };
    let field = |reason: String| FieldError::new("floor_plan.map", reason);
    let name = reference
        .as_str()
        .ok_or_else(|| field("must be the path of a map YAML file".into()))?;
    for key in [
        "image",
        "resolution",
        "origin",
        "negate",
        "occupied_thresh",
        "free_thresh",
        "mode",
    ] {
        if plan.contains_key(key) {
            return Err(FieldError::new(
                format!("floor_plan.{key}"),
                "comes from the map file named in floor_plan.map; give one or the other",
            ));
        }
    }
    let yaml_path = base.join(name);
    let text = read(&yaml_path, files::MAX_MAP_YAML_BYTES)
        .map_err(|e| field(format!("{}: {e}", yaml_path.display())))?;
    let text = String::from_utf8(text)
        .map_err(|_| field(format!("{}: not UTF-8 text", yaml_path.display())))?;
    let yaml: MapYaml = serde_saphyr::from_str(&text)
        .map_err(|e| field(format!("{}: {e}", yaml_path.display())))?;
    // YAML spells NaN and the infinities `.nan` and `.inf`, which JSON cannot carry: named here,
    // they would otherwise reach the document as `null` and be reported as a wrong type.
    let numbers = [
        ("resolution", yaml.resolution),
        ("occupied_thresh", yaml.occupied_thresh),
        ("free_thresh", yaml.free_thresh),
    ]
    .into_iter()
    .chain(yaml.origin.0.iter().map(|&v| ("origin", v)));
    for (key, value) in numbers {
        if !value.is_finite() {
            let written = if value.is_nan() {
                "NaN".to_string()
            } else {
                format!("{value}")
            };
            return Err(field(format!(
                "{}: {key}: must be a finite number, got {written}",
                yaml_path.display()
            )));
        }
    }
    let origin: [f64; 3] = yaml.origin.0.as_slice().try_into().map_err(|_| {
        field(format!(
            "{}: origin must have 3 elements [x, y, yaw], not {}",
            yaml_path.display(),
            yaml.origin.0.len()
        ))
    })?;
    let image_path = yaml_path
        .parent()
        .unwrap_or(Path::new("."))
        .join(&yaml.image);
    let image = read(&image_path, files::MAX_IMAGE_FILE_BYTES).map_err(|e| {
        field(format!(
            "{} (the image named by {}): {e}",
            image_path.display(),
            yaml_path.display()
        ))
    })?;
    plan.remove("map");
    let fields = serde_json::json!({
        "image": base64::engine::general_purpose::STANDARD.encode(image),
        "resolution": yaml.resolution,
        "origin": origin,
        "negate": yaml.negate,
        "occupied_thresh": yaml.occupied_thresh,
        "free_thresh": yaml.free_thresh,
        "mode": yaml.mode.unwrap_or_default(),
    });
    plan.extend(fields.as_object().expect("an object").clone());
    Ok(())
}

/// A grid of Nav2 cell values written as a map: the PGM image and the YAML naming it.
#[derive(Debug, Clone, PartialEq)]
pub struct EncodedMap {
    /// The map YAML (image, resolution, origin, negate, thresholds, mode).
    pub yaml: String,
    /// The binary (P5) PGM image, 8-bit grey, the map's top row first.
    pub pgm: Vec<u8>,
}

/// Writes `values` (Nav2 cell values, row-major from the *bottom* row, `width` per row) as a PGM
/// and its YAML (`image: {image_name}`), with the map's resolution and origin. `trinary` maps
/// (values 0, 100 and −1) use map_saver's pixels (254 free, 0 occupied, 205 unknown) with
/// thresholds 0.65 / 0.196: ROS's map_saver pair, under which 205 (occ 50/255 = 0.19608) reads
/// back as unknown — with Nav2's default free_thresh 0.25 it would read back as free; `scale` maps (values 0…100, a cost or speed mask) use `free_thresh 0, occupied_thresh
/// 1` as Nav2's speed-filter masks do, with the pixel 255 − 2.55·v rounded, which Nav2's
/// `rint(occ·100)` maps back to v exactly.
pub fn encode_map(
    values: &[i8],
    width: usize,
    resolution: f64,
    origin: [f64; 2],
    mode: MapMode,
    image_name: &str,
) -> EncodedMap {
    let height = values.len() / width.max(1);
    let mut pixels = vec![0u8; values.len()];
    for (r, row) in values.chunks_exact(width).enumerate() {
        let out = &mut pixels[(height - 1 - r) * width..(height - r) * width];
        for (p, &v) in out.iter_mut().zip(row) {
            *p = match mode {
                MapMode::Trinary => match v {
                    100 => 0,
                    0 => 254,
                    _ => 205,
                },
                MapMode::Scale => (255.0 - 2.55 * f64::from(v.clamp(0, 100))).round() as u8,
                MapMode::Raw => v.clamp(0, 100) as u8,
            };
        }
    }
    let mut pgm = Vec::with_capacity(pixels.len() + 32);
    image::codecs::pnm::PnmEncoder::new(&mut pgm)
        .with_subtype(image::codecs::pnm::PnmSubtype::Graymap(
            image::codecs::pnm::SampleEncoding::Binary,
        ))
        .encode(
            pixels.as_slice(),
            width as u32,
            height as u32,
            image::ExtendedColorType::L8,
        )
        .expect("encoding into memory cannot fail");
    let (occupied_thresh, free_thresh) = match mode {
        MapMode::Scale => (1.0, 0.0),
        _ => (0.65, 0.196),
    };
    let yaml = serde_saphyr::to_string(&MapYaml {
        image: image_name.to_string(),
        mode: Some(mode),
        resolution,
        origin: serde_saphyr::FlowSeq(vec![origin[0], origin[1], 0.0]),
        negate: Negate(false),
        occupied_thresh,
        free_thresh,
    })
    .expect("a map YAML always serialises");
    EncodedMap { yaml, pgm }
}

#[cfg(test)]
mod tests {
    use super::*;
    use irs_model::floorplan::{FloorPlan, MapIo, UnknownAs, decode_grey, nav2_value};
    use std::collections::HashMap;

    fn b64(bytes: &[u8]) -> String {
        base64::engine::general_purpose::STANDARD.encode(bytes)
    }

    fn plan(image: &[u8]) -> FloorPlan {
        FloorPlan {
            image: b64(image).into(),
            resolution: 0.5,
            origin: [-1.0, -2.0, 0.0],
            negate: Negate(false),
            occupied_thresh: 0.65,
            free_thresh: 0.25,
            mode: MapMode::Trinary,
            unknown_as: UnknownAs::Occupied,
            map_io: Default::default(),
            obstacle_height_m: None,
        }
    }

    /// A 3 × 2 P5 image: top row 0 (black), 254 (white), 205 (grey); bottom row 254, 254, 0.
    const P5: &[u8] = b"P5\n# a comment\n3 2\n255\n\x00\xfe\xcd\xfe\xfe\x00";

    fn files(entries: &[(&str, &[u8])]) -> HashMap<std::path::PathBuf, Vec<u8>> {
        entries
            .iter()
            .map(|(k, v)| (std::path::PathBuf::from(k), v.to_vec()))
            .collect()
    }

    #[test]
    fn a_map_reference_resolves_relative_to_the_scenario_and_the_yaml() {
        let fs = files(&[
            (
                "site/maps/floor.yaml",
                b"image: img/floor.pgm\nresolution: 0.5\norigin: [-1.0, -2.0, 0.0]\n\
                  negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\nextra_key: ignored\n",
            ),
            ("site/maps/img/floor.pgm", P5),
        ]);
        let read = |p: &Path, _: u64| {
            fs.get(p)
                .cloned()
                .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
        };
        let mut doc =
            serde_json::json!({"floor_plan": {"map": "maps/floor.yaml", "obstacle_height_m": 2.5}});
        resolve_map_reference(&mut doc, Path::new("site"), &read).unwrap();
        let resolved: FloorPlan = serde_json::from_value(doc["floor_plan"].clone()).unwrap();
        assert_eq!(
            resolved,
            FloorPlan {
                obstacle_height_m: Some(2.5),
                ..plan(P5)
            }
        );
        // A missing key or image names the reference.
        for (yaml, expected) in [
            (
                "image: img/floor.pgm\nresolution: 0.5\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n",
                "origin",
            ),
            (
                "image: nope.pgm\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n",
                "nope.pgm",
            ),
            (
                "image: img/floor.pgm\nresolution: 0.5\norigin: [0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n",
                "3 elements",
            ),
            (
                "image: img/floor.pgm\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: 2\noccupied_thresh: 0.65\nfree_thresh: 0.25\n",
                "negate",
            ),
            (
                "image: img/floor.pgm\nresolution: .nan\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n",
                "resolution: must be a finite number, got NaN",
            ),
            (
                "image: img/floor.pgm\nresolution: 0.5\norigin: [0, .NaN, 0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.25\n",
                "origin: must be a finite number, got NaN",
            ),
            (
                "image: img/floor.pgm\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: 0\noccupied_thresh: -.inf\nfree_thresh: 0.25\n",
                "occupied_thresh: must be a finite number, got -inf",
            ),
        ] {
            let mut fs = fs.clone();
            fs.insert("site/maps/floor.yaml".into(), yaml.as_bytes().to_vec());
            let read = |p: &Path, _: u64| {
                fs.get(p)
                    .cloned()
                    .ok_or_else(|| std::io::Error::from(std::io::ErrorKind::NotFound))
            };
            let mut doc = serde_json::json!({"floor_plan": {"map": "maps/floor.yaml"}});
            let e = resolve_map_reference(&mut doc, Path::new("site"), &read).unwrap_err();
            assert_eq!(e.field, "floor_plan.map");
            assert!(e.reason.contains(expected), "{expected}: {e}");
        }
    }

    #[cfg(unix)]
    #[test]
    fn an_image_that_is_not_a_regular_file_is_refused_unread() {
        let dir = std::env::temp_dir().join(format!("irs-mapfile-zero-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(
            dir.join("floor.yaml"),
            "image: /dev/zero\nresolution: 0.5\norigin: [0, 0, 0]\nnegate: 0\n\
             occupied_thresh: 0.65\nfree_thresh: 0.25\n",
        )
        .unwrap();
        let mut doc = serde_json::json!({"floor_plan": {"map": "floor.yaml"}});
        // Read as a plain file, /dev/zero would fill the memory.
        let e = resolve_map_reference(&mut doc, &dir, &files::read_regular).unwrap_err();
        assert_eq!(e.field, "floor_plan.map");
        assert!(
            e.reason.starts_with("/dev/zero (the image named by")
                && e.reason.ends_with(
                    "not a regular file (a character device); only regular files are read"
                ),
            "{e}"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn encoded_maps_decode_to_the_same_values() {
        let values: Vec<i8> = (0..=100).collect();
        let width = 101;
        let scale = encode_map(&values, width, 0.25, [1.0, 2.0], MapMode::Scale, "m.pgm");
        let yaml: MapYaml = serde_saphyr::from_str(&scale.yaml).unwrap();
        assert_eq!(yaml.image, "m.pgm");
        // One line, as map_server writes it (and people read it).
        assert!(
            scale
                .yaml
                .lines()
                .any(|l| l.starts_with("origin: [") && l.ends_with(']')),
            "{}",
            scale.yaml
        );
        let p = FloorPlan {
            image: b64(&scale.pgm).into(),
            resolution: yaml.resolution,
            origin: [yaml.origin.0[0], yaml.origin.0[1], yaml.origin.0[2]],
            negate: yaml.negate,
            occupied_thresh: yaml.occupied_thresh,
            free_thresh: yaml.free_thresh,
            mode: yaml.mode.unwrap(),
            ..plan(P5)
        };
        let grey = decode_grey(&scale.pgm).unwrap();
        // Humble's and Jazzy's map servers both read the values written.
        for map_io in [MapIo::Humble, MapIo::Jazzy] {
            let p = FloorPlan {
                map_io,
                ..p.clone()
            };
            let back: Vec<i8> = grey.pixels.iter().map(|&px| nav2_value(px, &p)).collect();
            assert_eq!(back, values, "{map_io:?}");
        }
        let keepout: Vec<i8> = (0..12).map(|k| [100, 0, -1][k % 3]).collect();
        let trinary = encode_map(&keepout, 4, 0.5, [0.0, 0.0], MapMode::Trinary, "k.pgm");
        let yaml: MapYaml = serde_saphyr::from_str(&trinary.yaml).unwrap();
        let p = FloorPlan {
            image: b64(&trinary.pgm).into(),
            free_thresh: yaml.free_thresh,
            occupied_thresh: yaml.occupied_thresh,
            ..plan(P5)
        };
        let grey = decode_grey(&trinary.pgm).unwrap();
        for map_io in [MapIo::Humble, MapIo::Jazzy] {
            let p = FloorPlan {
                map_io,
                ..p.clone()
            };
            let mut back: Vec<i8> = grey.pixels.iter().map(|&px| nav2_value(px, &p)).collect();
            // Image rows run from the top: flip them back to map rows.
            back = back.chunks(4).rev().flatten().copied().collect();
            assert_eq!(
                back, keepout,
                "occupied, free and unknown read back ({map_io:?})"
            );
        }
    }
}
