//! ROS occupancy-grid maps (`map.yaml` + `map.pgm`, the format of Nav2's map_server and of SLAM
//! tools), in and out (docs/scenarios.md "Floor plans").
//!
//! * In: a scenario's `floor_plan` holds the map YAML's fields and the image (base64). Pixels
//!   decode exactly as Nav2's `map_io` does — shade = pixel/255, occupancy = 1 − shade (or shade
//!   with `negate`), then the `trinary`, `scale` or `raw` rule with `occupied_thresh` and
//!   `free_thresh` to a cell value in {−1, 0…100}; image row 0 is the *top* of the map. A cell
//!   value of 100 (Nav2's "occupied", the costmap static layer's default lethal threshold)
//!   blocks, −1 (unknown) is what `unknown_as` says, anything else is free.
//! * Files (map YAML references, base64, maps written out for Nav2) are the answers crate's
//!   (`irs_answers::mapfile`): the model takes the image file's bytes.

use crate::geometry::Raster;
use crate::input::FieldError;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Largest floor-plan image side (pixels): 4096 px is 205 m at 0.05 m, larger than any single
/// floor we know of; it bounds the decoded raster at 16.8 Mpx (16.8 MB of flags).
pub const MAX_IMAGE_SIDE: u32 = 4096;

/// The map YAML's `mode`: how an occupancy becomes a cell value (Nav2 `MapMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapMode {
    /// occ > occupied_thresh → 100, occ < free_thresh → 0, otherwise unknown (−1).
    #[default]
    Trinary,
    /// As trinary, but between the thresholds the value is interpolated linearly to 0…100.
    Scale,
    /// The pixel value itself when it lies in 0…100, otherwise unknown.
    Raw,
}

/// Which Nav2 release's `map_io` arithmetic decodes the pixels. The two agree except on a pixel
/// whose occupancy falls exactly on a threshold (or within float32 rounding of it), which
/// Humble counts on the unknown side and Jazzy on the threshold's side, and in `scale` mode by
/// one step of rounding now and then.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MapIo {
    /// Humble and Iron (`nav2_map_server` up to 1.2): occupancy in double, occupied when
    /// `occ > occupied_thresh`, free when `occ < free_thresh`; `scale` rounds half to even
    /// (`std::rint`).
    #[default]
    Humble,
    /// Jazzy onward (the Eigen rewrite): occupancy in float32 (`pixel / 255.0f`), thresholds
    /// cast to float32, occupied when `occ ≥ occupied_thresh`, free when `occ ≤ free_thresh`
    /// (free checked last, so it wins a tie); `scale` in float32, rounded half away from zero.
    Jazzy,
}

impl MapIo {
    fn is_default(&self) -> bool {
        *self == MapIo::Humble
    }
}

/// What a pixel the map calls unknown (−1) is for radio purposes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum UnknownAs {
    /// Unknown space blocks links and cannot be driven (the safe reading of an unexplored map).
    #[default]
    Occupied,
    /// Unknown space is free: neither blocks links nor keeps the robot out.
    Free,
}

/// The YAML's `negate`: Nav2 reads 0/1 (or false/true). Written back as 0 or 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Negate(pub bool);

impl Serialize for Negate {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_u8(u8::from(self.0))
    }
}

impl<'de> Deserialize<'de> for Negate {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = Negate;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("0 or 1 (or false or true)")
            }
            fn visit_bool<E: serde::de::Error>(self, v: bool) -> Result<Negate, E> {
                Ok(Negate(v))
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Negate, E> {
                match v {
                    0 | 1 => Ok(Negate(v == 1)),
                    _ => Err(E::invalid_value(serde::de::Unexpected::Unsigned(v), &self)),
                }
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Negate, E> {
                match u64::try_from(v) {
                    Ok(v) => self.visit_u64(v),
                    Err(_) => Err(E::invalid_value(serde::de::Unexpected::Signed(v), &self)),
                }
            }
        }
        d.deserialize_any(Visitor)
    }
}

/// A scenario's floor plan: the map YAML's fields, the image and how to read it for radio.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FloorPlan {
    /// The image file (PGM P2/P5 or PNG, 8-bit grey) as the scenario document carries it, in
    /// base64: kept as text for the document's canonical form, decoded by the answers crate
    /// (the model takes the file's bytes, [`decode`]). Shared, because scenarios derived from
    /// this one (placement candidates) clone it.
    pub image: std::sync::Arc<str>,
    /// Pixel side (m).
    pub resolution: f64,
    /// [x, y, yaw] of the lower-left pixel's lower-left corner (m, m, rad); yaw must be 0.
    pub origin: [f64; 3],
    /// Occupancy = shade when set (white is occupied), else 1 − shade (black is occupied).
    pub negate: Negate,
    /// Occupancy above which a pixel is occupied (100), in (0, 1]; above `free_thresh`.
    pub occupied_thresh: f64,
    /// Occupancy below which a pixel is free (0), in [0, 1); below `occupied_thresh`.
    pub free_thresh: f64,
    /// How occupancy becomes a cell value; default `trinary`, as in Nav2.
    #[serde(default)]
    pub mode: MapMode,
    /// What an unknown (−1) pixel is for radio and driving; default `occupied`.
    #[serde(default)]
    pub unknown_as: UnknownAs,
    /// Which Nav2's decoding to reproduce; default `humble`. Left out of the canonical form
    /// when it is the default, so floor plans written before it existed keep their ids.
    #[serde(default, skip_serializing_if = "MapIo::is_default")]
    pub map_io: MapIo,
    /// How high the occupied pixels stand (m); default: the ceiling (walls).
    #[serde(default, deserialize_with = "crate::input::present")]
    pub obstacle_height_m: Option<f64>,
}

/// Nav2's cell value of one 8-bit grey pixel (`nav2_map_server::loadMapFromFile`): 100
/// occupied, 0 free, −1 unknown, 1…99 in between (`scale` and `raw` only), in the arithmetic
/// of the release `plan.map_io` names.
pub fn nav2_value(pixel: u8, plan: &FloorPlan) -> i8 {
    if plan.map_io == MapIo::Jazzy {
        return nav2_value_jazzy(pixel, plan);
    }
    let shade = f64::from(pixel) / 255.0;
    let occ = if plan.negate.0 { shade } else { 1.0 - shade };
    match plan.mode {
        MapMode::Trinary | MapMode::Scale if plan.occupied_thresh < occ => 100,
        MapMode::Trinary | MapMode::Scale if occ < plan.free_thresh => 0,
        MapMode::Trinary => -1,
        MapMode::Scale => ((occ - plan.free_thresh) / (plan.occupied_thresh - plan.free_thresh)
            * 100.0)
            .round_ties_even() as i8,
        MapMode::Raw => i8::try_from(pixel).ok().filter(|v| *v <= 100).unwrap_or(-1),
    }
}

/// [`nav2_value`] as Jazzy's `map_io.cpp` computes it: an Eigen float32 array compared with
/// the thresholds converted to float32.
fn nav2_value_jazzy(pixel: u8, plan: &FloorPlan) -> i8 {
    let shade = f32::from(pixel) / 255.0f32;
    let occ = if plan.negate.0 { shade } else { 1.0f32 - shade };
    // The YAML's doubles, as Eigen converts a scalar to the array's type.
    let (free, occupied) = (plan.free_thresh as f32, plan.occupied_thresh as f32);
    match plan.mode {
        MapMode::Trinary | MapMode::Scale if occ <= free => 0,
        MapMode::Trinary | MapMode::Scale if occ >= occupied => 100,
        MapMode::Trinary => -1,
        MapMode::Scale => (((occ - free) / (occupied - free)) * 100.0f32).round() as i8,
        MapMode::Raw => i8::try_from(pixel).ok().filter(|v| *v <= 100).unwrap_or(-1),
    }
}

/// An 8-bit grey image, rows from the top.
pub struct GreyImage {
    /// Columns (pixels).
    pub width: usize,
    /// Rows (pixels).
    pub height: usize,
    /// Row-major from the image's top row.
    pub pixels: Vec<u8>,
}

/// Decodes a PGM (P2 or P5) or PNG file holding 8-bit grey pixels.
pub fn decode_grey(bytes: &[u8]) -> Result<GreyImage, String> {
    let pgm = bytes.starts_with(b"P2") || bytes.starts_with(b"P5");
    let png = bytes.starts_with(b"\x89PNG\r\n\x1a\n");
    if !pgm && !png {
        return Err("not a PGM (magic P2 or P5) or PNG image".into());
    }
    let format = if pgm {
        image::ImageFormat::Pnm
    } else {
        image::ImageFormat::Png
    };
    let mut reader = image::ImageReader::with_format(std::io::Cursor::new(bytes), format);
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    // Room for the largest allowed image at 16 bits, so an oversized one is refused by the
    // side limits above with a clear message rather than by an allocation failure.
    limits.max_alloc = Some(2 * u64::from(MAX_IMAGE_SIDE).pow(2) + (1 << 20));
    reader.limits(limits);
    let refusal = |e: image::ImageError| match e {
        image::ImageError::Limits(_) => {
            format!("larger than {MAX_IMAGE_SIDE} × {MAX_IMAGE_SIDE} pixels")
        }
        other => format!("cannot be decoded: {other}"),
    };
    let decoder = reader.into_decoder().map_err(refusal)?;
    // The pixel type is read from the header, before the pixels: a colour image three or four
    // times the size of a grey one would otherwise pass the side limits and then fail the
    // allocation limit, refused as too large instead of as colour.
    use image::{ColorType, ImageDecoder};
    let colour = match decoder.color_type() {
        ColorType::L8 => None,
        ColorType::L16 => {
            return Err(
                "16-bit images are not supported; save the map with 8-bit grey pixels".into(),
            );
        }
        ColorType::Rgb8 | ColorType::Rgb16 | ColorType::Rgb32F => Some("RGB"),
        ColorType::Rgba8 | ColorType::Rgba16 | ColorType::Rgba32F => Some("RGBA"),
        ColorType::La8 | ColorType::La16 => Some("grey with an alpha channel"),
        _ => Some("of a colour type other than 8-bit grey"),
    };
    if let Some(colour) = colour {
        return Err(format!(
            "is {colour}: a floor plan is 8-bit grey; convert it to grayscale (a greyscale \
             PGM or PNG, 8 bits a pixel, no alpha)"
        ));
    }
    let decoded = image::DynamicImage::from_decoder(decoder).map_err(refusal)?;
    let (width, height) = (decoded.width() as usize, decoded.height() as usize);
    // A header may declare a side of 0 pixels, which decodes to no pixels at all: a map of
    // nothing, refused here rather than divided by later.
    if width == 0 || height == 0 {
        return Err(format!(
            "is {width} × {height} pixels: a map needs at least one"
        ));
    }
    Ok(GreyImage {
        width,
        height,
        pixels: decoded.into_luma8().into_raw(),
    })
}

/// Decodes a floor plan's image file (`file`: the bytes of the PGM or PNG that `plan.image`
/// carries) into the raster the channel model walks. `ceiling_m` is the default obstacle
/// height. Errors name the `floor_plan` field at fault.
pub fn decode(plan: &FloorPlan, file: &[u8], ceiling_m: f64) -> Result<Raster, FieldError> {
    let image = decode_grey(file).map_err(|e| FieldError::new("floor_plan.image", e))?;
    let (w, h) = (image.width, image.height);
    let mut occupied = vec![false; w * h];
    for (y, row) in image.pixels.chunks_exact(w).enumerate() {
        // Image row y is map row h − 1 − y (Nav2: data[w·(h − y − 1) + x]).
        let out = &mut occupied[(h - 1 - y) * w..(h - y) * w];
        for (cell, &pixel) in out.iter_mut().zip(row) {
            *cell = match nav2_value(pixel, plan) {
                100 => true,
                -1 => plan.unknown_as == UnknownAs::Occupied,
                _ => false,
            };
        }
    }
    Ok(Raster::new(
        w,
        h,
        plan.resolution,
        [plan.origin[0], plan.origin[1]],
        plan.obstacle_height_m.unwrap_or(ceiling_m),
        &occupied,
    ))
}

/// Checks the fields of a floor plan that do not need the image.
pub fn check_fields(plan: &FloorPlan) -> Result<(), FieldError> {
    let err = |field: &str, reason: &str| Err(FieldError::new(field, reason));
    if !(plan.resolution.is_finite() && plan.resolution > 0.0) {
        return err(
            "floor_plan.resolution",
            "must be a positive number of metres",
        );
    }
    if plan.origin.iter().any(|v| !v.is_finite()) {
        return err("floor_plan.origin", "must be finite");
    }
    if plan.origin[2] != 0.0 {
        return err(
            "floor_plan.origin",
            "a non-zero yaw is not supported: the map's axes must be the scenario's x and y \
             (rotate the image, or the scenario, so that yaw is 0)",
        );
    }
    if !(plan.free_thresh.is_finite() && plan.free_thresh >= 0.0) {
        return err("floor_plan.free_thresh", "must lie in [0, 1)");
    }
    if !(plan.occupied_thresh.is_finite() && plan.occupied_thresh <= 1.0) {
        return err("floor_plan.occupied_thresh", "must lie in (0, 1]");
    }
    if plan.free_thresh >= plan.occupied_thresh {
        return err(
            "floor_plan.free_thresh",
            "must be smaller than occupied_thresh",
        );
    }
    if let Some(h) = plan.obstacle_height_m
        && !(h.is_finite() && h > 0.0)
    {
        return err("floor_plan.obstacle_height_m", "must be positive");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan() -> FloorPlan {
        FloorPlan {
            image: "(the file's base64)".into(),
            resolution: 0.5,
            origin: [-1.0, -2.0, 0.0],
            negate: Negate(false),
            occupied_thresh: 0.65,
            free_thresh: 0.25,
            mode: MapMode::Trinary,
            unknown_as: UnknownAs::Occupied,
            map_io: MapIo::Humble,
            obstacle_height_m: None,
        }
    }

    /// A 3 × 2 P5 image: top row 0 (black), 254 (white), 205 (grey); bottom row 254, 254, 0.
    const P5: &[u8] = b"P5\n# a comment\n3 2\n255\n\x00\xfe\xcd\xfe\xfe\x00";

    #[test]
    fn pixels_decode_as_nav2_does() {
        let mut p = plan();
        // Trinary: black occupied, white free; 205 → occ 0.196 < 0.25 → free.
        let cells: Vec<i8> = [0u8, 254, 205, 128]
            .iter()
            .map(|&v| nav2_value(v, &p))
            .collect();
        assert_eq!(cells, [100, 0, 0, -1]);
        p.negate = Negate(true);
        assert_eq!(nav2_value(0, &p), 0);
        assert_eq!(nav2_value(255, &p), 100);
        p.negate = Negate(false);
        p.mode = MapMode::Scale;
        // occ(128) = 127/255 = 0.498; (0.498 − 0.25)/0.4·100 = 62.0 → 62.
        assert_eq!(nav2_value(128, &p), 62);
        assert_eq!(nav2_value(0, &p), 100);
        p.mode = MapMode::Raw;
        assert_eq!(nav2_value(37, &p), 37);
        assert_eq!(nav2_value(100, &p), 100);
        assert_eq!(nav2_value(101, &p), -1);
    }

    /// Humble and Jazzy differ exactly where their arithmetics do: on a pixel whose occupancy
    /// is a threshold. The expected differences were found by evaluating both arithmetics in
    /// NumPy (float64 with strict comparisons, float32 with ≥/≤) over every 8-bit pixel: with
    /// thresholds 0.6/0.2, pixel 102 (occupancy 1 − 102/255 = 0.6) is unknown for Humble and
    /// occupied for Jazzy; with 0.8/0.4, pixels 51 (0.8) and 153 (0.4) are unknown for Humble,
    /// occupied and free for Jazzy; with map_server's 0.65/0.25 they agree on every pixel.
    #[test]
    fn humble_and_jazzy_differ_only_on_a_threshold() {
        // (thresholds, and the pixels where they differ: (pixel, Humble, Jazzy)).
        type Differences = &'static [(u8, i8, i8)];
        let cases: [((f64, f64), Differences); 3] = [
            ((0.6, 0.2), &[(102, -1, 100)]),
            ((0.8, 0.4), &[(51, -1, 100), (153, -1, 0)]),
            ((0.65, 0.25), &[]),
        ];
        for ((occupied, free), differences) in cases {
            let mut p = plan();
            (p.occupied_thresh, p.free_thresh) = (occupied, free);
            for pixel in 0..=255u8 {
                p.map_io = MapIo::Humble;
                let humble = nav2_value(pixel, &p);
                p.map_io = MapIo::Jazzy;
                let jazzy = nav2_value(pixel, &p);
                let expected = differences
                    .iter()
                    .find(|d| d.0 == pixel)
                    .map_or((humble, humble), |d| (d.1, d.2));
                assert_eq!(
                    (humble, jazzy),
                    expected,
                    "pixel {pixel} at {occupied}/{free}"
                );
            }
        }
    }

    #[test]
    fn image_rows_are_flipped_and_unknown_follows_unknown_as() {
        let mut p = plan();
        p.mode = MapMode::Trinary;
        const IMAGE: &[u8] = b"P2\n3 2\n255\n0 254 128\n254 254 0\n";
        let r = decode(&p, IMAGE, 3.0).unwrap();
        assert_eq!((r.width, r.height, r.obstacle_height), (3, 2, 3.0));
        // Map row 0 is the image's bottom row.
        assert_eq!(r.occupancy(), [false, false, true, true, false, true]);
        p.unknown_as = UnknownAs::Free;
        p.obstacle_height_m = Some(1.25);
        let r = decode(&p, IMAGE, 3.0).unwrap();
        assert_eq!(r.occupancy(), [false, false, true, true, false, false]);
        assert_eq!(r.obstacle_height, 1.25);
        assert_eq!(r.extent(), [[-1.0, 0.5], [-2.0, -1.0]]);
    }

    #[test]
    fn png_and_pgm_of_the_same_pixels_decode_alike() {
        let mut png = Vec::new();
        image::codecs::png::PngEncoder::new(&mut png)
            .write_image(
                &[0u8, 254, 205, 254, 254, 0],
                3,
                2,
                image::ExtendedColorType::L8,
            )
            .unwrap();
        use image::ImageEncoder;
        let a = decode(&plan(), P5, 2.0).unwrap();
        let b = decode(&plan(), &png, 2.0).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn bad_images_are_rejected_with_a_reason() {
        let reason = |bytes: &[u8]| decode(&plan(), bytes, 2.0).unwrap_err();
        let cases: [(&[u8], &str); 7] = [
            (b"P6\n1 1\n255\n\x00\x00\x00", "not a PGM"),
            (b"P5\n3 2\n255\n\x00\xfe", "cannot be decoded"),
            (b"P5\n1 1\n65535\n\x00\x00", "16-bit"),
            (b"GIF89a", "not a PGM"),
            (b"P5\n5000 1\n255\n", "larger than 4096"),
            (b"P5\n0 3\n255\n", "at least one"),
            (b"P5\n3 0\n255\n", "at least one"),
        ];
        for (bytes, expected) in cases {
            let e = reason(bytes);
            assert_eq!(e.field, "floor_plan.image");
            assert!(e.reason.contains(expected), "{expected}: {e}");
        }
    }

    #[test]
    fn colour_images_are_refused_as_colour_not_as_too_large() {
        let png = |width: u32, height: u32, colour: image::ExtendedColorType| {
            let channels = colour.channel_count() as usize;
            let pixels = vec![0u8; width as usize * height as usize * channels];
            let mut png = Vec::new();
            image::codecs::png::PngEncoder::new(&mut png)
                .write_image(&pixels, width, height, colour)
                .unwrap();
            png
        };
        use image::{ExtendedColorType, ImageEncoder};
        for (bytes, expected) in [
            (png(2, 2, ExtendedColorType::Rgb8), "is RGB"),
            (png(2, 2, ExtendedColorType::Rgba8), "is RGBA"),
            (png(2, 2, ExtendedColorType::La8), "alpha"),
            // Within the side limits, but three bytes a pixel pass the allocation limit that
            // fits a grey image: this one used to be refused as larger than 4096 × 4096.
            (png(4096, 2900, ExtendedColorType::Rgb8), "is RGB"),
        ] {
            let e = decode(&plan(), &bytes, 2.0).unwrap_err();
            assert!(e.reason.contains(expected), "{expected}: {e}");
            assert!(e.reason.contains("convert it to grayscale"), "{e}");
        }
    }

    #[test]
    fn a_pgm_with_a_smaller_maxval_is_scaled_as_graphicsmagick_does() {
        // maxval 100: 100 is white (shade 1), 0 black, 50 mid-grey (shade 0.5 → unknown).
        let mut p = plan();
        p.unknown_as = UnknownAs::Free;
        let r = decode(&p, b"P2\n3 1\n100\n100 0 50\n", 2.0).unwrap();
        assert_eq!(r.occupancy(), [false, true, false]);
    }

    #[test]
    fn field_checks_name_the_field() {
        type Edit = fn(&mut FloorPlan);
        let cases: [(Edit, &str); 4] = [
            (|p| p.origin[2] = 0.5, "floor_plan.origin"),
            (|p| p.resolution = 0.0, "floor_plan.resolution"),
            (|p| p.free_thresh = 0.7, "floor_plan.free_thresh"),
            (|p| p.occupied_thresh = 1.5, "floor_plan.occupied_thresh"),
        ];
        for (mutate, field) in cases {
            let mut p = plan();
            mutate(&mut p);
            assert_eq!(check_fields(&p).unwrap_err().field, field);
        }
    }
}
