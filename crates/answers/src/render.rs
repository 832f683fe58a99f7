//! PNG pictures of radio maps and paths, for people rather than programs (paper Figs. 4–6 and
//! 8–9 in spirit). A picture explains itself:
//!
//! * each cell a square coloured by its value on viridis (dark purple → teal → yellow, readable
//!   with colour-blindness and in grey scale), from the map's minimum to its maximum; obstacles
//!   grey, free cells with no value (rate maps: no configuration serves every SRU) black;
//! * with a threshold, cells below it are dimmed (the feasible map Π, eq. 14) and the threshold is
//!   marked on the colour bar;
//! * axes with ticks in metres, a colour bar with its range and unit, and a title;
//! * markers: the AP (white square), the IRS (magenta bar along its wall), the SRUs (white
//!   circles), start (green) and goal (red) — also when the path is infeasible, so the reason
//!   (an occupied or below-threshold end) can be seen; the path in white.
//!
//! North (+y) is up. Text uses the public-domain 8×8 bitmap font of `font8x8`.

use font8x8::UnicodeFonts;
use irs_model::input::FieldError;
use irs_model::planner::PathAnswer;
use irs_model::radiomap::{MapKind, RadioMap, Unit};
use irs_model::scenario::Scenario;

/// Largest plot side in pixels (the map itself, without margins).
pub const MAX_SIDE_PX: usize = 4096;
/// Largest pixels per cell a caller may ask for.
pub const MAX_CELL_PX: usize = 32;

/// What a picture shows on top of the map (a threshold, a path and its ends) and at what scale.
#[derive(Debug, Clone, Default)]
pub struct RenderOptions {
    /// The unit the cells are coloured in and the threshold is given in (default: the map's).
    pub unit: Option<Unit>,
    /// Dim the cells below this value.
    pub threshold: Option<f64>,
    /// Cells (flat indices) of a path, start first.
    pub path: Vec<usize>,
    /// The start and goal cells to mark (flat indices), feasible or not.
    pub ends: Option<(usize, usize)>,
    /// Pixels per cell; default: the longer side of the plot fits in 768 px
    /// ([`default_cell_px`]).
    pub cell_px: Option<usize>,
    /// A fleet's routes: per robot its cell (flat index) at every step, drawn in a colour of
    /// its own with its request index at its start.
    pub fleet: Vec<Vec<usize>>,
    /// A tick on every fleet route every this many steps.
    pub tick_steps: usize,
}

impl RenderOptions {
    /// The picture of a path answer: its threshold dims the cells below it, its waypoints and
    /// its two ends are drawn.
    pub fn for_path<P>(map: &RadioMap, answer: &PathAnswer<P>) -> Self {
        RenderOptions {
            unit: Some(answer.unit),
            threshold: answer.threshold,
            path: answer
                .waypoints
                .iter()
                .map(|w| map.grid.index(w.i, w.j))
                .collect(),
            ends: Some((
                map.grid.index(answer.start.i, answer.start.j),
                map.grid.index(answer.goal.i, answer.goal.j),
            )),
            cell_px: None,
            ..RenderOptions::default()
        }
    }

    /// The picture of a fleet plan: each served robot's route with a tick every
    /// `tick_s` seconds (at least every step).
    pub fn for_fleet(plan: &irs_model::fleet::FleetPlan, tick_s: f64) -> Self {
        RenderOptions {
            unit: Some(plan.unit),
            fleet: plan.robots.iter().map(|r| r.cells.clone()).collect(),
            tick_steps: ((tick_s / plan.dt_s).round() as usize).max(1),
            ..RenderOptions::default()
        }
    }
}

type Rgb = [u8; 3];

/// Viridis at five stops (low → high).
const SCALE: [[f64; 3]; 5] = [
    [68.0, 1.0, 84.0],
    [59.0, 82.0, 139.0],
    [33.0, 145.0, 140.0],
    [94.0, 201.0, 98.0],
    [253.0, 231.0, 37.0],
];
const BACKGROUND: Rgb = [255, 255, 255];
const INK: Rgb = [0, 0, 0];
const OBSTACLE: Rgb = [128, 128, 128];
const NO_VALUE: Rgb = [0, 0, 0];
const PATH: Rgb = [255, 255, 255];
const START: Rgb = [0, 200, 0];
const GOAL: Rgb = [230, 0, 0];
const IRS: Rgb = [230, 0, 230];
/// Fleet routes, one colour per robot in turn (Okabe–Ito, distinguishable with colour-blind
/// vision).
const ROUTES: [Rgb; 7] = [
    [230, 159, 0],
    [86, 180, 233],
    [0, 158, 115],
    [240, 228, 66],
    [0, 114, 178],
    [213, 94, 0],
    [204, 121, 167],
];
const DEVICE: Rgb = [255, 255, 255];
/// Factor applied to the colour of cells below the threshold.
const DIM: f64 = 0.3;

fn colour(t: f64) -> Rgb {
    let x = t.clamp(0.0, 1.0) * (SCALE.len() - 1) as f64;
    let k = (x.floor() as usize).min(SCALE.len() - 2);
    let f = x - k as f64;
    let mix = |c: usize| (SCALE[k][c] * (1.0 - f) + SCALE[k + 1][c] * f).round() as u8;
    [mix(0), mix(1), mix(2)]
}

/// Pixels per cell so that the longer side of the plot fits in 768 px (at least 1, at most
/// [`MAX_CELL_PX`]): big enough to read on a laptop screen, small enough to embed.
pub fn default_cell_px(map: &RadioMap) -> usize {
    (768 / map.grid.nx.max(map.grid.ny)).clamp(1, MAX_CELL_PX)
}

/// Where everything goes in the picture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layout {
    /// Pixels per cell.
    pub cell_px: usize,
    /// Top-left pixel of the plot area.
    pub left: usize,
    /// Rows above the plot area (the title and the labels): the y of its top-left pixel.
    pub top: usize,
    /// Width of the plot area (pixels): nx × `cell_px`.
    pub plot_width: usize,
    /// Height of the plot area (pixels): ny × `cell_px`.
    pub plot_height: usize,
    /// Width of the whole picture (pixels), margins, colour bar and title included.
    pub width: usize,
    /// Height of the whole picture (pixels), margins included.
    pub height: usize,
    /// Text glyphs are 8 × `text_scale` pixels.
    text_scale: usize,
}

impl Layout {
    /// The layout for a map shown in `unit`; `None` when the plot would exceed [`MAX_SIDE_PX`].
    pub fn new(map: &RadioMap, unit: Unit, cell_px: Option<usize>) -> Option<Layout> {
        let cell_px = cell_px.unwrap_or_else(|| default_cell_px(map));
        let (plot_width, plot_height) = (map.grid.nx * cell_px, map.grid.ny * cell_px);
        if plot_width > MAX_SIDE_PX || plot_height > MAX_SIDE_PX {
            return None;
        }
        // Big plots get double-size text so labels stay legible next to them.
        let text_scale = if plot_width.max(plot_height) >= 400 {
            2
        } else {
            1
        };
        let glyph = 8 * text_scale;
        // Left: tick labels like "-10.5"; top: the title line, then the axis and unit labels;
        // right: the colour bar and its labels; bottom: tick labels and the x caption.
        let (left, top) = (7 * glyph, 4 * glyph);
        let (right, bottom) = (12 * glyph, 5 * glyph);
        let title_width = glyph * (title(map, unit).chars().count() + 2);
        Some(Layout {
            cell_px,
            left,
            top,
            plot_width,
            plot_height,
            width: (left + plot_width + right).max(title_width),
            height: top + plot_height + bottom,
            text_scale,
        })
    }

    /// The pixel (column, row) of the centre of cell (i, j).
    pub fn cell_centre(&self, map: &RadioMap, i: usize, j: usize) -> (usize, usize) {
        (
            self.left + i * self.cell_px + self.cell_px / 2,
            self.top + (map.grid.ny - 1 - j) * self.cell_px + self.cell_px / 2,
        )
    }

    /// The pixel of a point (x, y) in metres (cell centres are pixel-cell centres).
    fn point(&self, map: &RadioMap, x: f64, y: f64) -> (f64, f64) {
        let g = &map.grid;
        let px = self.left as f64 + ((x - g.x_min) / g.resolution_m + 0.5) * self.cell_px as f64;
        let py = self.top as f64
            + ((g.ny - 1) as f64 - (y - g.y_min) / g.resolution_m + 0.5) * self.cell_px as f64;
        (px, py)
    }
}

/// An RGB canvas with the few drawing operations the picture needs.
struct Canvas {
    width: usize,
    height: usize,
    pixels: Vec<u8>,
}

impl Canvas {
    fn new(width: usize, height: usize) -> Canvas {
        let mut pixels = vec![0; width * height * 3];
        pixels
            .chunks_mut(3)
            .for_each(|p| p.copy_from_slice(&BACKGROUND));
        Canvas {
            width,
            height,
            pixels,
        }
    }

    fn set(&mut self, x: i64, y: i64, rgb: Rgb) {
        if x >= 0 && y >= 0 && (x as usize) < self.width && (y as usize) < self.height {
            let at = (y as usize * self.width + x as usize) * 3;
            self.pixels[at..at + 3].copy_from_slice(&rgb);
        }
    }

    fn fill(&mut self, x0: i64, y0: i64, w: i64, h: i64, rgb: Rgb) {
        for y in y0..y0 + h {
            for x in x0..x0 + w {
                self.set(x, y, rgb);
            }
        }
    }

    fn frame(&mut self, x0: i64, y0: i64, w: i64, h: i64, rgb: Rgb) {
        for x in x0..x0 + w {
            self.set(x, y0, rgb);
            self.set(x, y0 + h - 1, rgb);
        }
        for y in y0..y0 + h {
            self.set(x0, y, rgb);
            self.set(x0 + w - 1, y, rgb);
        }
    }

    fn disk(&mut self, cx: f64, cy: f64, radius: f64, rgb: Rgb) {
        let r = radius.ceil() as i64;
        let (x0, y0) = (cx.round() as i64, cy.round() as i64);
        for dy in -r..=r {
            for dx in -r..=r {
                if ((dx * dx + dy * dy) as f64) <= radius * radius {
                    self.set(x0 + dx, y0 + dy, rgb);
                }
            }
        }
    }

    /// Text with its top-left corner at (x, y); characters the font lacks are skipped.
    fn text(&mut self, x: i64, y: i64, text: &str, scale: usize, rgb: Rgb) {
        let s = scale as i64;
        for (k, c) in text.chars().enumerate() {
            let Some(glyph) = font8x8::BASIC_FONTS
                .get(c)
                .or_else(|| font8x8::GREEK_FONTS.get(c))
            else {
                continue;
            };
            let gx = x + 8 * s * k as i64;
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..8 {
                    if bits & (1 << col) != 0 {
                        self.fill(gx + col * s, y + row as i64 * s, s, s, rgb);
                    }
                }
            }
        }
    }

    fn text_width(text: &str, scale: usize) -> i64 {
        (8 * scale * text.chars().count()) as i64
    }
}

/// Tick positions from `low` to `high` at a 1-2-5 step giving about `target` ticks.
fn ticks(low: f64, high: f64, target: usize) -> Vec<f64> {
    let span = (high - low).abs().max(f64::MIN_POSITIVE);
    let raw = span / target.max(1) as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * magnitude)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * magnitude);
    let first = (low / step).ceil() as i64;
    let last = (high / step).floor() as i64;
    (first..=last).map(|k| k as f64 * step).collect()
}

/// A tick label without trailing zeros ("−10", "2.5", "−59.6").
fn label(v: f64) -> String {
    let text = format!("{:.2}", if v.abs() < 1e-9 { 0.0 } else { v });
    text.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// Encodes the picture of `map` (with the devices of its `scenario`) as PNG, coloured in the
/// options' unit; `Ok(None)` when the plot would exceed [`MAX_SIDE_PX`] at the requested cell
/// size, an error naming `unit` when the map cannot be read in it.
pub fn png(
    map: &RadioMap,
    scenario: &Scenario,
    options: &RenderOptions,
) -> Result<Option<Vec<u8>>, FieldError> {
    let unit = options.unit.unwrap_or(map.native_unit());
    let values = map.values_in(unit)?;
    let Some(layout) = Layout::new(map, unit, options.cell_px) else {
        return Ok(None);
    };
    let mut canvas = Canvas::new(layout.width, layout.height);
    let finite = values.iter().copied().filter(|v| v.is_finite());
    let (low, high) = finite.fold((None, None), |(lo, hi): (Option<f64>, Option<f64>), v| {
        (
            Some(lo.map_or(v, |l| l.min(v))),
            Some(hi.map_or(v, |h| h.max(v))),
        )
    });
    let (low, high) = (low.unwrap_or(0.0), high.unwrap_or(1.0));
    let span = if high > low { high - low } else { 1.0 };
    draw_cells(&mut canvas, map, &values, &layout, options, low, span);
    draw_axes(&mut canvas, map, &layout, unit);
    let bar = ColourBar {
        threshold: options.threshold,
        low,
        high,
        unit,
    };
    draw_colour_bar(&mut canvas, &layout, &bar);
    draw_devices(&mut canvas, map, scenario, &layout);
    draw_fleet(&mut canvas, map, &layout, options);
    if let Some((start, goal)) = options.ends {
        for (cell, rgb) in [(start, START), (goal, GOAL)] {
            let (i, j) = map.grid.cell_of(cell);
            let (cx, cy) = layout.cell_centre(map, i, j);
            let radius = (layout.cell_px as f64 * 0.45).max(4.0);
            canvas.disk(cx as f64, cy as f64, radius + 1.5, INK);
            canvas.disk(cx as f64, cy as f64, radius, rgb);
        }
    }
    let mut out = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut out, layout.width as u32, layout.height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().expect("PNG header to memory");
        writer
            .write_image_data(&canvas.pixels)
            .expect("PNG data to memory");
    }
    Ok(Some(out))
}

/// The colour bar's range, threshold mark and unit.
struct ColourBar {
    threshold: Option<f64>,
    low: f64,
    high: f64,
    unit: Unit,
}

fn draw_cells(
    canvas: &mut Canvas,
    map: &RadioMap,
    values: &[f64],
    layout: &Layout,
    options: &RenderOptions,
    low: f64,
    span: f64,
) {
    let (nx, ny) = (map.grid.nx, map.grid.ny);
    let mut cell_rgb = vec![[0u8; 3]; nx * ny];
    for (k, rgb) in cell_rgb.iter_mut().enumerate() {
        let v = values[k];
        *rgb = if map.occupied[k] {
            OBSTACLE
        } else if !v.is_finite() {
            NO_VALUE
        } else {
            let c = colour((v - low) / span);
            match options.threshold {
                Some(t) if v < t => c.map(|x| (x as f64 * DIM) as u8),
                _ => c,
            }
        };
    }
    for &c in &options.path {
        cell_rgb[c] = PATH;
    }
    let ppc = layout.cell_px as i64;
    for i in 0..nx {
        for j in 0..ny {
            let x = layout.left as i64 + i as i64 * ppc;
            let y = layout.top as i64 + (ny - 1 - j) as i64 * ppc;
            canvas.fill(x, y, ppc, ppc, cell_rgb[map.grid.index(i, j)]);
        }
    }
}

fn draw_axes(canvas: &mut Canvas, map: &RadioMap, layout: &Layout, unit: Unit) {
    let s = layout.text_scale;
    let glyph = 8 * s as i64;
    let (left, top) = (layout.left as i64, layout.top as i64);
    let (w, h) = (layout.plot_width as i64, layout.plot_height as i64);
    canvas.frame(left - 1, top - 1, w + 2, h + 2, INK);
    let g = &map.grid;
    let (x_max, y_max) = (
        g.x_min + (g.nx - 1) as f64 * g.resolution_m,
        g.y_min + (g.ny - 1) as f64 * g.resolution_m,
    );
    for x in ticks(g.x_min, x_max, 8) {
        let (px, _) = layout.point(map, x, g.y_min);
        let px = px.round() as i64;
        canvas.fill(px, top + h, 1, glyph / 2, INK);
        let text = label(x);
        let tw = Canvas::text_width(&text, s);
        canvas.text(px - tw / 2, top + h + glyph * 3 / 4, &text, s, INK);
    }
    for y in ticks(g.y_min, y_max, 8) {
        let (_, py) = layout.point(map, g.x_min, y);
        let py = py.round() as i64;
        canvas.fill(left - glyph / 2, py, glyph / 2, 1, INK);
        let text = label(y);
        let tw = Canvas::text_width(&text, s);
        canvas.text(left - glyph * 3 / 4 - tw, py - glyph / 2, &text, s, INK);
    }
    let caption = "x (m)";
    let cw = Canvas::text_width(caption, s);
    canvas.text(left + w / 2 - cw / 2, top + h + glyph * 2, caption, s, INK);
    canvas.text(left - glyph * 6, top - glyph * 2, "y (m)", s, INK);
    canvas.text(glyph / 2, glyph / 2, &title(map, unit), s, INK);
}

/// "channel power gain map, phases 2" / "MRU rate map, NOMA, phases continuous", with the
/// unit shown when it is not the map's own ("…, shown in dBm").
fn title(map: &RadioMap, unit: Unit) -> String {
    let kind = match (map.key.kind, map.key.access) {
        (MapKind::Rate, Some(access)) => format!(
            "MRU rate map, {}, phases {}",
            access.to_string().to_uppercase(),
            map.key.phases
        ),
        _ => format!("channel power gain map, phases {}", map.key.phases),
    };
    if unit == map.native_unit() {
        kind
    } else {
        format!("{kind}, shown in {}", unit.symbol())
    }
}

fn draw_colour_bar(canvas: &mut Canvas, layout: &Layout, bar: &ColourBar) {
    let &ColourBar {
        threshold,
        low,
        high,
        unit,
    } = bar;
    let s = layout.text_scale;
    let glyph = 8 * s as i64;
    let x0 = (layout.left + layout.plot_width) as i64 + glyph * 2;
    let (top, h) = (layout.top as i64, layout.plot_height as i64);
    let bar_width = glyph * 2;
    let span = if high > low { high - low } else { 1.0 };
    for row in 0..h {
        let t = 1.0 - row as f64 / (h - 1).max(1) as f64;
        canvas.fill(x0, top + row, bar_width, 1, colour(t));
    }
    canvas.frame(x0 - 1, top - 1, bar_width + 2, h + 2, INK);
    let y_of = |v: f64| top + ((high - v) / span * (h - 1) as f64).round() as i64;
    let mut marks = vec![low, high];
    marks.extend(
        ticks(low, high, 5)
            .into_iter()
            .filter(|t| (t - low).abs() > span * 0.08 && (high - t).abs() > span * 0.08),
    );
    for v in marks {
        let y = y_of(v);
        canvas.fill(x0 + bar_width, y, glyph / 2, 1, INK);
        canvas.text(
            x0 + bar_width + glyph * 3 / 4,
            y - glyph / 2,
            &label(v),
            s,
            INK,
        );
    }
    if let Some(t) = threshold.filter(|t| *t >= low && *t <= high) {
        let y = y_of(t);
        canvas.fill(x0 - glyph / 2, y - 1, bar_width + glyph, 3, INK);
        canvas.fill(x0 - glyph / 2, y, bar_width + glyph, 1, BACKGROUND);
    }
    canvas.text(x0, top - glyph * 2, unit.symbol(), s, INK);
}

/// Each robot's cells as a square of its colour, an ink tick every `tick_steps` steps, and its
/// index at its start.
fn draw_fleet(canvas: &mut Canvas, map: &RadioMap, layout: &Layout, options: &RenderOptions) {
    let side = ((layout.cell_px as f64 * 0.6).round() as i64).max(2);
    let tick = (layout.cell_px as f64 * 0.25).max(1.5);
    for (r, cells) in options.fleet.iter().enumerate() {
        let rgb = ROUTES[r % ROUTES.len()];
        for (k, &c) in cells.iter().enumerate() {
            let (i, j) = map.grid.cell_of(c);
            let (cx, cy) = layout.cell_centre(map, i, j);
            let (cx, cy) = (cx as i64, cy as i64);
            // Outlined in ink: the route colours also occur on the map's scale.
            canvas.fill(
                cx - side / 2 - 1,
                cy - side / 2 - 1,
                side + 2,
                side + 2,
                INK,
            );
            canvas.fill(cx - side / 2, cy - side / 2, side, side, rgb);
            if k > 0 && options.tick_steps > 0 && k % options.tick_steps == 0 {
                canvas.disk(cx as f64, cy as f64, tick, INK);
            }
        }
        if let Some(&first) = cells.first() {
            let (i, j) = map.grid.cell_of(first);
            let (cx, cy) = layout.cell_centre(map, i, j);
            let s = layout.text_scale;
            canvas.text(
                cx as i64 + side,
                cy as i64 - 8 * s as i64,
                &r.to_string(),
                s,
                INK,
            );
        }
    }
}

fn draw_devices(canvas: &mut Canvas, map: &RadioMap, scenario: &Scenario, layout: &Layout) {
    let s = layout.text_scale;
    let glyph = (8 * s) as f64;
    let radius = (layout.cell_px as f64 * 0.35).max(3.0 * s as f64);
    let marker_label = |canvas: &mut Canvas, px: f64, py: f64, text: &str| {
        let (x, y) = ((px + radius + 2.0) as i64, (py - glyph / 2.0) as i64);
        let w = Canvas::text_width(text, s);
        canvas.fill(x - 1, y - 1, w + 2, glyph as i64 + 2, BACKGROUND);
        canvas.text(x, y, text, s, INK);
    };
    let several = scenario.surfaces().len() > 1;
    for (k, irs) in scenario.surfaces().iter().enumerate() {
        // The surface as a bar along its wall (at least three cells long, to stay visible).
        let n = irs.normal;
        let along = [-n[1], n[0]];
        let norm = along[0].hypot(along[1]).max(f64::MIN_POSITIVE);
        let width = irs.width_m();
        let half = (width / 2.0).max(1.5 * map.grid.resolution_m);
        let steps = 200;
        for k in 0..=steps {
            let t = -half + 2.0 * half * k as f64 / steps as f64;
            let (px, py) = layout.point(
                map,
                irs.center[0] + t * along[0] / norm,
                irs.center[1] + t * along[1] / norm,
            );
            canvas.disk(px, py, radius * 0.6, IRS);
        }
        let (px, py) = layout.point(map, irs.center[0], irs.center[1]);
        let label = if several {
            format!("IRS {k}")
        } else {
            "IRS".to_string()
        };
        marker_label(canvas, px, py - glyph, &label);
    }
    let aps = scenario.access_points();
    for (k, ap) in aps.iter().enumerate() {
        let (px, py) = layout.point(map, ap.position[0], ap.position[1]);
        let r = radius.round() as i64;
        canvas.fill(
            px as i64 - r - 1,
            py as i64 - r - 1,
            2 * r + 3,
            2 * r + 3,
            INK,
        );
        canvas.fill(px as i64 - r, py as i64 - r, 2 * r + 1, 2 * r + 1, DEVICE);
        let label = if aps.len() > 1 {
            format!("AP {k}")
        } else {
            "AP".to_string()
        };
        marker_label(canvas, px, py, &label);
    }
    for (k, sru) in scenario.srus.iter().enumerate() {
        let (px, py) = layout.point(map, sru.position[0], sru.position[1]);
        canvas.disk(px, py, radius + 1.0, INK);
        canvas.disk(px, py, radius, DEVICE);
        marker_label(canvas, px, py, &format!("SRU{k}"));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::ScenarioDocument;
    use irs_model::phases::PhaseMode;
    use irs_model::planner::{self, Threshold};
    use irs_model::radiomap::{MapKey, Progress};

    fn decode(bytes: Vec<u8>) -> (usize, usize, Vec<u8>) {
        let decoder = png::Decoder::new(std::io::Cursor::new(bytes));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size().unwrap()];
        let info = reader.next_frame(&mut buf).unwrap();
        (info.width as usize, info.height as usize, buf)
    }

    #[test]
    fn picture_shows_obstacles_path_endpoints_devices_and_colour_bar() {
        let s = Scenario::builtin("small-test").unwrap();
        let key = MapKey::gain("t", &s, PhaseMode::Continuous).unwrap();
        let map = crate::map::build(&s, &key, &Progress::default()).unwrap();
        let answer = planner::plan(
            &map,
            map.native_unit(),
            Default::default(),
            [0.5, 0.5],
            [5.5, 3.5],
            Threshold::Max,
            1.0,
        )
        .unwrap();
        let options = RenderOptions::for_path(&map, &answer);
        let layout = Layout::new(&map, map.native_unit(), None).unwrap();
        let (width, height, buf) = decode(png(&map, &s, &options).unwrap().unwrap());
        assert_eq!((width, height), (layout.width, layout.height));
        assert!(width > layout.plot_width && height > layout.plot_height);
        let pixel = |(x, y): (usize, usize)| {
            let at = (y * width + x) * 3;
            [buf[at], buf[at + 1], buf[at + 2]]
        };
        let cell = |i, j| pixel(layout.cell_centre(&map, i, j));
        // The obstacle's centre cell (3, 2) m is grey; start and goal are green and red; an
        // inner waypoint is white.
        let (oi, oj) = map.grid.snap(3.0, 2.0).unwrap();
        assert_eq!(cell(oi, oj), OBSTACLE);
        assert_eq!(cell(answer.start.i, answer.start.j), START);
        assert_eq!(cell(answer.goal.i, answer.goal.j), GOAL);
        let mid = &answer.waypoints[answer.waypoints.len() / 2];
        assert_eq!(cell(mid.i, mid.j), PATH);
        // The AP marker is drawn at the AP, the SRU's at the SRU.
        let (ai, aj) = map
            .grid
            .snap(s.ap().position[0], s.ap().position[1])
            .unwrap();
        assert_eq!(cell(ai, aj), DEVICE);
        // The colour bar runs from the brightest colour at the top to the darkest at the bottom,
        // and the axes carry ink (tick labels) left of and below the plot.
        let bar_x = layout.left + layout.plot_width + 16 * layout.text_scale + 4;
        assert_eq!(pixel((bar_x, layout.top)), colour(1.0));
        assert_eq!(
            pixel((bar_x, layout.top + layout.plot_height - 1)),
            colour(0.0)
        );
        let ink_below = (layout.top + layout.plot_height + 4..height)
            .flat_map(|y| (layout.left..layout.left + layout.plot_width).map(move |x| (x, y)))
            .filter(|&p| pixel(p) == INK)
            .count();
        assert!(
            ink_below > 50,
            "x tick labels drawn ({ink_below} ink pixels)"
        );
    }

    #[test]
    fn infeasible_ends_are_still_marked_and_sizes_are_bounded() {
        let s = Scenario::builtin("small-test").unwrap();
        let key = MapKey::gain("t", &s, PhaseMode::Continuous).unwrap();
        let map = crate::map::build(&s, &key, &Progress::default()).unwrap();
        let answer = planner::plan(
            &map,
            map.native_unit(),
            Default::default(),
            [0.5, 0.5],
            [5.5, 3.5],
            Threshold::Value(1e9),
            1.0,
        )
        .unwrap();
        assert!(!answer.feasible);
        let options = RenderOptions::for_path(&map, &answer);
        let layout = Layout::new(&map, map.native_unit(), None).unwrap();
        let (width, _, buf) = decode(png(&map, &s, &options).unwrap().unwrap());
        let (x, y) = layout.cell_centre(&map, answer.start.i, answer.start.j);
        let at = (y * width + x) * 3;
        assert_eq!([buf[at], buf[at + 1], buf[at + 2]], START);
        let too_big = RenderOptions {
            cell_px: Some(MAX_SIDE_PX),
            ..RenderOptions::default()
        };
        assert!(png(&map, &s, &too_big).unwrap().is_none());
    }

    #[test]
    fn scale_ticks_and_labels() {
        assert_eq!(colour(0.0), [68, 1, 84]);
        assert_eq!(colour(1.0), [253, 231, 37]);
        assert_eq!(colour(2.0), colour(1.0));
        assert_eq!(ticks(-10.0, 10.0, 8), vec![-10.0, -5.0, 0.0, 5.0, 10.0]);
        assert_eq!(ticks(0.0, 6.0, 8), vec![0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(
            ticks(-64.2, -59.6, 5),
            vec![-64.0, -63.0, -62.0, -61.0, -60.0]
        );
        assert_eq!(label(-10.0), "-10");
        assert_eq!(label(2.5), "2.5");
        assert_eq!(label(-0.0), "0");
    }
}
