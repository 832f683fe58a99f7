//! PNG pictures of radio maps and paths, for people rather than programs (paper Figs. 4–6 and
//! 8–9 in spirit): each cell a square coloured by its value on a perceptually ordered scale
//! (dark blue → teal → yellow, from the map's minimum to its maximum), obstacles grey, cells with
//! no value black; with a threshold, cells below it are dimmed (the feasible map Π, eq. 14); a
//! path is drawn in white with the start green and the goal red. North (+y) is up.

use crate::planner::PathAnswer;
use crate::radiomap::RadioMap;

/// Largest image side in pixels.
pub const MAX_SIDE_PX: usize = 4096;

#[derive(Debug, Clone, Default)]
pub struct RenderOptions {
    /// Dim the cells below this value.
    pub threshold: Option<f64>,
    /// Cells (flat indices) of a path, start first.
    pub path: Vec<usize>,
}

impl RenderOptions {
    /// The picture of a path answer: its threshold dims the cells below it, its waypoints drawn.
    pub fn for_path(map: &RadioMap, answer: &PathAnswer) -> Self {
        RenderOptions {
            threshold: answer.threshold,
            path: answer
                .waypoints
                .iter()
                .map(|w| map.grid.index(w.i, w.j))
                .collect(),
        }
    }
}

/// Colour stops of the value scale (low → high).
const SCALE: [[f64; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];
const OBSTACLE: [u8; 3] = [128, 128, 128];
const NO_VALUE: [u8; 3] = [0, 0, 0];
const PATH: [u8; 3] = [255, 255, 255];
const START: [u8; 3] = [0, 200, 0];
const GOAL: [u8; 3] = [230, 0, 0];

fn colour(t: f64) -> [u8; 3] {
    let x = t.clamp(0.0, 1.0) * (SCALE.len() - 1) as f64;
    let k = (x.floor() as usize).min(SCALE.len() - 2);
    let f = x - k as f64;
    let mix = |c: usize| (SCALE[k][c] * (1.0 - f) + SCALE[k + 1][c] * f).round() as u8;
    [mix(0), mix(1), mix(2)]
}

/// Pixels per cell so that the longer side fits in 1024 px (at least 1, at most 16).
pub fn pixels_per_cell(map: &RadioMap) -> usize {
    (1024 / map.grid.nx.max(map.grid.ny)).clamp(1, 16)
}

/// Encodes the picture of `map` as PNG.
pub fn png(map: &RadioMap, options: &RenderOptions) -> Vec<u8> {
    let (nx, ny) = (map.grid.nx, map.grid.ny);
    let ppc = pixels_per_cell(map);
    let (width, height) = ((nx * ppc).min(MAX_SIDE_PX), (ny * ppc).min(MAX_SIDE_PX));
    let stats = map.stats();
    let (low, high) = (stats.min.unwrap_or(0.0), stats.max.unwrap_or(1.0));
    let span = if high > low { high - low } else { 1.0 };
    let mut cell_rgb = vec![[0u8; 3]; nx * ny];
    for (k, rgb) in cell_rgb.iter_mut().enumerate() {
        let v = map.values[k];
        *rgb = if map.occupied[k] {
            OBSTACLE
        } else if !v.is_finite() {
            NO_VALUE
        } else {
            let c = colour((v - low) / span);
            match options.threshold {
                Some(t) if v < t => c.map(|x| (x as f64 * 0.3) as u8),
                _ => c,
            }
        };
    }
    for &c in &options.path {
        cell_rgb[c] = PATH;
    }
    if let (Some(&first), Some(&last)) = (options.path.first(), options.path.last()) {
        cell_rgb[first] = START;
        cell_rgb[last] = GOAL;
    }
    let mut pixels = vec![0u8; width * height * 3];
    for py in 0..height {
        let j = ny - 1 - (py * ny / height); // row 0 of the image is the room's far (+y) wall
        for px in 0..width {
            let i = px * nx / width;
            let at = (py * width + px) * 3;
            pixels[at..at + 3].copy_from_slice(&cell_rgb[map.grid.index(i, j)]);
        }
    }
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().expect("PNG header to memory");
        writer
            .write_image_data(&pixels)
            .expect("PNG data to memory");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::phases::PhaseMode;
    use crate::planner::{self, Threshold};
    use crate::radiomap::{self, MapKey, Progress};
    use crate::scenario::Scenario;

    #[test]
    fn picture_shows_obstacles_path_and_endpoints() {
        let s = Scenario::builtin("small-test").unwrap();
        let key = MapKey::gain("t", &s, PhaseMode::Continuous).unwrap();
        let map = radiomap::build(&s, &key, &Progress::default()).unwrap();
        let answer = planner::plan(&map, [0.5, 0.5], [5.5, 3.5], Threshold::Max, 1.0).unwrap();
        let bytes = png(&map, &RenderOptions::for_path(&map, &answer));
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        let ppc = pixels_per_cell(&map);
        assert_eq!(
            (info.width as usize, info.height as usize),
            (map.grid.nx * ppc, map.grid.ny * ppc)
        );
        let pixel = |i: usize, j: usize| {
            let (px, py) = (i * ppc + ppc / 2, (map.grid.ny - 1 - j) * ppc + ppc / 2);
            let at = (py * info.width as usize + px) * 3;
            [buf[at], buf[at + 1], buf[at + 2]]
        };
        // The obstacle's centre cell (3, 2) m is grey; start and goal are green and red; an inner
        // waypoint is white.
        let (oi, oj) = map.grid.snap(3.0, 2.0).unwrap();
        assert_eq!(pixel(oi, oj), OBSTACLE);
        assert_eq!(pixel(answer.start.i, answer.start.j), START);
        assert_eq!(pixel(answer.goal.i, answer.goal.j), GOAL);
        let mid = &answer.waypoints[answer.waypoints.len() / 2];
        assert_eq!(pixel(mid.i, mid.j), PATH);
    }

    #[test]
    fn scale_runs_from_dark_to_bright() {
        assert_eq!(colour(0.0), [68, 1, 84]);
        assert_eq!(colour(1.0), [253, 231, 37]);
        assert_eq!(colour(2.0), colour(1.0));
    }
}
