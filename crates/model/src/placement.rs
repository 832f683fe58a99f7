//! Where to mount the IRS (or the AP): candidate poses ranked by an objective on their gain
//! maps (docs/model.md §7). The question a site planner asks before buying a surface.
//!
//! Candidates are explicit poses, or wall segments sampled every `step_m` with the normal
//! facing into the room (an IRS's samples kept half its width from the segment's ends, so the
//! whole surface lies on the segment). Objectives: `coverage` (η(γ), paper eq. 44), `max_threshold` (the
//! widest-path value between a start and a goal) and `distance` (the shortest path at γ;
//! infeasible ranks last).
//!
//! Moving one IRS changes only its own terms of λ(θ) = |h̃ + Σ_s w̃_sᵀθ_s|² + τ, so the direct
//! link (its blockage, path loss and phase) and every other surface's terms are evaluated once
//! per cell and shared by every candidate; a candidate costs its own surface's terms alone. With
//! continuous phases the best gain is (|h̃| + Σ_s ‖w̃_s‖₁)² + τ (eq. 12), so a cell keeps
//! |h̃| + Σ_{s≠k} ‖w̃_s‖₁; with b-bit phases each element's quantised phase depends only on ∠h̃
//! and its own ∠w̃_n, so a cell keeps the complex sum h̃ + Σ_{s≠k} w̃_sᵀθ_s. With continuous
//! phases and `coherent` surfaces both parts are evaluated a row at a time, as the map builder
//! does ([`ChannelModel::closed_form_row`]): a candidate costs one vectorised link budget per
//! cell and AP, no phasor. Moving the AP changes every link, so each AP candidate's map is
//! built in full by the ordinary builder.

use crate::channel::{C64, ChannelModel, ClosedFormRow, RowTerms};
use crate::geometry::Obstructions;
use crate::input::FieldError;
use crate::numerics::l1_norm;
use crate::phases::{PhaseMode, quantise_phase};
use crate::planner::CellGraph;
use crate::radiomap::{self, Cancelled, MapKey, Progress, WorkError, body::coverage};
use crate::scenario::{Grid, Grouping, Irs, Scenario};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Largest number of candidates in one search.
pub const MAX_CANDIDATES: usize = 4096;
/// Largest search, in cell evaluations (candidates × grid cells × APs): about a minute of one
/// core at N = 60, so a search never holds a worker for longer than a large map build does.
pub const MAX_WORK_CELLS: usize = 100_000_000;

/// What moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum What {
    /// One IRS of the scenario (candidates: poses, or walls); its size and grouping are kept.
    #[default]
    Irs,
    /// One AP of the scenario (candidates: positions, or walls); its power and carrier are kept.
    Ap,
}

/// An IRS pose: where its centre is and which way it faces.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pose {
    /// Centre of the surface (x, y, z) (m).
    pub center: [f64; 3],
    /// Unit normal, into the room and not vertical (as a scenario's `irs.normal`).
    pub normal: [f64; 3],
}

/// A wall segment to sample candidates along.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Segment {
    /// One end (x, y) (m), the first sample.
    pub from: [f64; 2],
    /// The other end (x, y) (m), a sample when the length is a whole number of steps.
    pub to: [f64; 2],
}

/// The candidates of a search: explicit IRS poses, explicit AP positions, or wall segments
/// sampled every `step_m` at `height_m` (default: the moving device's present height).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Candidates {
    /// IRS candidates given one by one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub poses: Vec<Pose>,
    /// AP candidates (x, y, z) (m) given one by one.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub positions: Vec<[f64; 3]>,
    /// Segments to sample every `step_m`; an IRS sample faces the free side.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub walls: Vec<Segment>,
    /// Spacing of the samples along `walls` (m, > 0); required with `walls`, refused without.
    #[serde(
        default,
        deserialize_with = "crate::input::present",
        skip_serializing_if = "Option::is_none"
    )]
    pub step_m: Option<f64>,
    /// Height (m) of the wall samples, default the moving device's; poses and positions carry
    /// their own.
    #[serde(
        default,
        deserialize_with = "crate::input::present",
        skip_serializing_if = "Option::is_none"
    )]
    pub height_m: Option<f64>,
}

/// What a candidate is scored by.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Objective {
    /// η(γ), the share of free cells at or above the threshold (higher is better).
    Coverage {
        /// γ (dB) a free cell must reach to count.
        threshold: f64,
    },
    /// The largest threshold for which a path joins start and goal (higher is better).
    MaxThreshold {
        /// One end of the path (x, y) (m), snapped to a cell.
        start: [f64; 2],
        /// The other end (x, y) (m), snapped to a cell.
        goal: [f64; 2],
    },
    /// The shortest path's length at the threshold (shorter is better; infeasible last).
    Distance {
        /// γ (dB) every cell of the path must reach.
        threshold: f64,
        /// Where the path starts (x, y) (m), snapped to a cell.
        start: [f64; 2],
        /// Where the path ends (x, y) (m), snapped to a cell.
        goal: [f64; 2],
    },
}

impl Objective {
    /// The unit of the score (gain maps are in dB).
    pub fn unit(&self) -> &'static str {
        match self {
            Objective::Coverage { .. } => "fraction",
            Objective::MaxThreshold { .. } => "dB",
            Objective::Distance { .. } => "m",
        }
    }
}

/// A placement search: what moves, where it may go, what is better.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Search {
    /// What moves; default an IRS.
    #[serde(default)]
    pub what: What,
    /// Which IRS (or AP) of the scenario moves, in scenario order.
    #[serde(default)]
    pub index: usize,
    /// Where it may go.
    pub candidates: Candidates,
    /// What is better.
    pub objective: Objective,
    /// The gain maps' phase mode (continuous or bits; default continuous).
    #[serde(
        default,
        deserialize_with = "crate::input::present",
        skip_serializing_if = "Option::is_none"
    )]
    pub phases: Option<PhaseMode>,
}

/// One candidate, before scoring.
#[derive(Debug, Clone)]
pub struct Candidate {
    /// The IRS centre or AP position to try (x, y, z) (m).
    pub center: [f64; 3],
    /// IRS candidates only.
    pub normal: Option<[f64; 3]>,
    /// The scenario with the device moved there, or why that is not a valid scenario.
    pub scenario: Result<Scenario, FieldError>,
}

/// A scored candidate, as the answer lists it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Ranked {
    /// 1 for the best.
    pub rank: usize,
    /// The IRS centre or AP position (x, y, z) (m).
    pub center: [f64; 3],
    /// The IRS candidate's normal; absent for an AP.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub normal: Option<[f64; 3]>,
    /// The objective's value (null when infeasible: no path, or start or goal occupied).
    pub score: Option<f64>,
    /// The id of the candidate's scenario (the base with the device moved).
    pub scenario_id: String,
    /// The id of the candidate's gain map (with the search's phase mode).
    pub map_id: String,
}

/// A candidate that is not a valid scenario (e.g. a wall sample on no wall, or facing away).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Rejected {
    /// The IRS centre or AP position (x, y, z) (m).
    pub center: [f64; 3],
    /// The IRS candidate's normal; absent for an AP.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub normal: Option<[f64; 3]>,
    /// Why the moved scenario is invalid: the field error, as text.
    pub reason: String,
}

/// The answer to a search; the same body from the CLI and the API.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PlacementAnswer {
    /// The id of the base scenario the search moved a device of.
    pub scenario_id: String,
    /// What moved.
    pub what: What,
    /// Which IRS or AP moved, in scenario order.
    pub index: usize,
    /// Candidates are scored on gain maps (the only kind placement uses).
    pub map_kind: &'static str,
    /// The phase mode the gain maps were built with (continuous unless the search said bits).
    pub phases: PhaseMode,
    /// The objective, as the search gave it.
    pub objective: Objective,
    /// The score's unit: `fraction`, `dB` or `m`.
    pub unit: &'static str,
    /// Best first; ties keep the candidates' order.
    pub candidates: Vec<Ranked>,
    /// The candidates that are not valid scenarios, in the candidates' order.
    pub rejected: Vec<Rejected>,
}

/// The scenarios of the best candidates, to register and build so their map ids answer.
pub struct Placement {
    /// The answer's body.
    pub answer: PlacementAnswer,
    /// The ranked candidates' scenarios, best first (as `answer.candidates`).
    pub scenarios: Vec<Scenario>,
}

/// Checks a search and lists its candidates, each with its scenario (or the reason it has
/// none). Everything a search could fail on is found here, before any map is computed.
pub fn candidates(base: &Scenario, search: &Search) -> Result<Vec<Candidate>, FieldError> {
    let c = &search.candidates;
    let moving_height = match search.what {
        What::Irs => {
            let irs = base.surfaces().get(search.index).ok_or_else(|| {
                FieldError::new(
                    "index",
                    format!(
                        "the scenario has {} IRS(s); placement moves one of them (its size and \
                         grouping are kept)",
                        base.surfaces().len()
                    ),
                )
            })?;
            if !c.positions.is_empty() {
                return Err(FieldError::new(
                    "candidates.positions",
                    "positions are AP candidates; an IRS needs poses (center and normal)",
                ));
            }
            irs.center[2]
        }
        What::Ap => {
            let ap = base
                .access_points()
                .get(search.index)
                .ok_or_else(|| FieldError::new("index", "the scenario has no AP of that index"))?;
            if !c.poses.is_empty() {
                return Err(FieldError::new(
                    "candidates.poses",
                    "poses are IRS candidates; an AP needs positions",
                ));
            }
            ap.position[2]
        }
    };
    if search.phases == Some(PhaseMode::None) || base.surfaces().is_empty() {
        return Err(FieldError::new(
            "phases",
            "placement compares gain maps with the IRS at work: phases must be continuous or \
             bits, and the scenario needs an IRS",
        ));
    }
    let height = c.height_m.unwrap_or(moving_height);
    if !height.is_finite() {
        return Err(FieldError::new("candidates.height_m", "must be finite"));
    }
    if c.walls.is_empty() != c.step_m.is_none() {
        return Err(FieldError::new(
            "candidates.step_m",
            "wall candidates need both walls and step_m (and step_m only applies to walls)",
        ));
    }
    let mut out: Vec<([f64; 3], Option<[f64; 3]>)> = Vec::new();
    for pose in &c.poses {
        out.push((pose.center, Some(pose.normal)));
    }
    for p in &c.positions {
        out.push((*p, None));
    }
    if let Some(step) = c.step_m {
        let obstructions = base.obstructions();
        if !(step.is_finite() && step > 0.0) {
            return Err(FieldError::new("candidates.step_m", "must be positive"));
        }
        for (k, wall) in c.walls.iter().enumerate() {
            let (dx, dy) = (wall.to[0] - wall.from[0], wall.to[1] - wall.from[1]);
            let length = dx.hypot(dy);
            if !length.is_finite() || length <= 0.0 {
                return Err(FieldError::new(
                    format!("candidates.walls[{k}]"),
                    "a wall needs two distinct, finite ends",
                ));
            }
            // Whole steps along the wall, both ends included when the length allows.
            let samples = (length / step + 1e-9).floor();
            if samples + out.len() as f64 >= MAX_CANDIDATES as f64 {
                return Err(FieldError::new(
                    "candidates.step_m",
                    format!("more than {MAX_CANDIDATES} candidates"),
                ));
            }
            // An IRS sample nearer a segment's end than half the surface's width moves inward
            // until the whole surface lies on the segment: one centred on a room's corner
            // would reach into the side wall (and is refused, see `Scenario` validation).
            let inset = match search.what {
                What::Irs => base.surfaces()[search.index].width_m() / 2.0 / length,
                What::Ap => 0.0,
            };
            let mut previous = None;
            for i in 0..=samples as usize {
                let mut t = i as f64 * step / length;
                if inset <= 0.5 {
                    t = t.clamp(inset, 1.0 - inset);
                }
                if previous == Some(t) {
                    continue;
                }
                previous = Some(t);
                let (x, y) = (wall.from[0] + t * dx, wall.from[1] + t * dy);
                let normal = match search.what {
                    What::Irs => Some(inward_normal(
                        base,
                        &obstructions,
                        [x, y, height],
                        [dx / length, dy / length],
                    )),
                    What::Ap => None,
                };
                out.push(([x, y, height], normal));
            }
        }
    }
    if out.is_empty() {
        return Err(FieldError::new("candidates", "no candidate given"));
    }
    if out.len() > MAX_CANDIDATES {
        return Err(FieldError::new(
            "candidates",
            format!("more than {MAX_CANDIDATES} candidates"),
        ));
    }
    let aps = base.access_points().len();
    let work = out
        .len()
        .saturating_mul(base.grid().cells())
        .saturating_mul(aps);
    if work > MAX_WORK_CELLS {
        return Err(FieldError::new(
            "candidates",
            format!(
                "{} candidates × {} cells × {aps} AP(s) = {work} cell evaluations exceed the \
                 limit of {MAX_WORK_CELLS}: fewer candidates (a larger step_m) or a coarser grid",
                out.len(),
                base.grid().cells()
            ),
        ));
    }
    check_objective(base, &search.objective)?;
    let moved = |center: [f64; 3], normal: Option<[f64; 3]>| match (search.what, normal) {
        (What::Irs, Some(normal)) => {
            let irs = Irs {
                center,
                normal,
                ..base.surfaces()[search.index].clone()
            };
            base.with_surface(search.index, irs)
        }
        _ => base.with_ap_at(search.index, center),
    };
    Ok(out
        .into_par_iter()
        .map(|(center, normal)| Candidate {
            center,
            normal,
            scenario: moved(center, normal).map(|mut s| {
                s.name = Some(candidate_name(base.name.as_deref(), search.what, center));
                s
            }),
        })
        .collect())
}

/// A candidate's scenario name: its parent's and where the device went, `warehouse @ IRS
/// (29.75, -5.5)` (an AP with its height), so that kept candidates tell themselves apart in a
/// listing. A long parent name is cut, with an ellipsis, to keep the whole within
/// [`MAX_NAME_CHARS`](crate::scenario::MAX_NAME_CHARS).
fn candidate_name(parent: Option<&str>, what: What, at: [f64; 3]) -> String {
    // Millimetres are as fine as a mounting position is meant.
    let mm = |v: f64| {
        let text = format!("{v:.3}");
        let text = text.trim_end_matches('0').trim_end_matches('.');
        if text == "-0" {
            "0".to_string()
        } else {
            text.to_string()
        }
    };
    let place = match what {
        What::Irs => format!("IRS ({}, {})", mm(at[0]), mm(at[1])),
        What::Ap => format!("AP ({}, {}, {})", mm(at[0]), mm(at[1]), mm(at[2])),
    };
    let Some(parent) = parent else {
        return place;
    };
    let room = crate::scenario::MAX_NAME_CHARS - place.chars().count() - " @ ".len();
    if parent.chars().count() <= room {
        format!("{parent} @ {place}")
    } else {
        let cut: String = parent.chars().take(room - 1).collect();
        format!("{cut}… @ {place}")
    }
}

/// The horizontal normal of a wall sample that faces into the room: of the two perpendiculars
/// to the wall, the one with free floor 5 cm in front and a wall, an obstacle or the room's end
/// 5 cm behind; the first perpendicular when neither or both qualify (the candidate's own
/// validation then says why it fails).
fn inward_normal(
    base: &Scenario,
    obstructions: &Obstructions,
    at: [f64; 3],
    along: [f64; 2],
) -> [f64; 3] {
    // Far enough to step off the face, no thicker than the thinnest wall a floor plan draws
    // (one 0.05 m pixel).
    const PROBE_M: f64 = 0.05;
    let r = &base.room;
    let solid = |x: f64, y: f64| {
        x < r.x_min
            || x > r.x_max
            || y < r.y_min
            || y > r.y_max
            || obstructions.solid_at([x, y, at[2]])
    };
    let left = [-along[1], along[0]];
    for n in [left, [-left[0], -left[1]]] {
        let front = solid(at[0] + n[0] * PROBE_M, at[1] + n[1] * PROBE_M);
        let behind = solid(at[0] - n[0] * PROBE_M, at[1] - n[1] * PROBE_M);
        if behind && !front {
            // + 0.0 writes −0 as 0.
            return [n[0] + 0.0, n[1] + 0.0, 0.0];
        }
    }
    [left[0] + 0.0, left[1] + 0.0, 0.0]
}

fn check_objective(base: &Scenario, objective: &Objective) -> Result<(), FieldError> {
    let grid = base.grid();
    let inside = |field: &str, p: [f64; 2]| {
        grid.snap(p[0], p[1]).map(|_| ()).ok_or_else(|| {
            FieldError::new(
                format!("objective.{field}"),
                format!("({}, {}) lies outside the room", p[0], p[1]),
            )
        })
    };
    let finite = |t: f64| {
        if t.is_finite() {
            Ok(())
        } else {
            Err(FieldError::new(
                "objective.threshold",
                "must be a finite number",
            ))
        }
    };
    match *objective {
        Objective::Coverage { threshold } => finite(threshold),
        Objective::MaxThreshold { start, goal } => {
            inside("start", start)?;
            inside("goal", goal)
        }
        Objective::Distance {
            threshold,
            start,
            goal,
        } => {
            finite(threshold)?;
            inside("start", start)?;
            inside("goal", goal)
        }
    }
}

/// The objective's value on a map's values (None: infeasible).
fn score(grid: &Grid, values: &[f64], occupied: &[bool], objective: &Objective) -> Option<f64> {
    let graph = CellGraph {
        grid,
        values,
        occupied,
    };
    let cell = |p: [f64; 2]| {
        let (i, j) = grid.snap(p[0], p[1]).expect("checked inside the room");
        grid.index(i, j)
    };
    match *objective {
        Objective::Coverage { threshold } => Some(coverage(values, occupied, threshold)),
        Objective::MaxThreshold { start, goal } => {
            graph.widest_path_threshold(cell(start), cell(goal))
        }
        Objective::Distance {
            threshold,
            start,
            goal,
        } => graph
            .shortest_path(cell(start), cell(goal), threshold)
            .ok()
            .map(|p| p.distance_m),
    }
}

/// Orders scores best first: higher is better except for distances; infeasible last; equal
/// scores keep the candidates' order (the sort is stable).
fn rank(scores: &mut [(usize, Option<f64>)], objective: &Objective) {
    let lower_is_better = matches!(objective, Objective::Distance { .. });
    scores.sort_by(|a, b| match (a.1, b.1) {
        (Some(x), Some(y)) if lower_is_better => x.total_cmp(&y),
        (Some(x), Some(y)) => y.total_cmp(&x),
        (Some(_), None) => std::cmp::Ordering::Less,
        (None, Some(_)) => std::cmp::Ordering::Greater,
        (None, None) => std::cmp::Ordering::Equal,
    });
}

/// Per AP and free cell, what every IRS candidate shares: the direct link and the surfaces that
/// stay put (see the module doc).
struct Shared {
    /// |h̃| + Σ_{s≠k} ‖w̃_s‖₁ (continuous) or h̃ + Σ_{s≠k} w̃_sᵀθ_s (bits), per AP per cell.
    field: Vec<Vec<C64>>,
    /// τ_direct + Σ_{s≠k} τ_s, per AP per cell.
    tau: Vec<Vec<f64>>,
}

/// The terms of surface `s` of `model` at `user`: (its amplitude or complex sum, τ_s).
fn surface_part(
    model: &ChannelModel,
    s: usize,
    user: [f64; 3],
    mode: PhaseMode,
    w: &mut [C64],
    theta: &mut [f64],
) -> (C64, f64) {
    let tau = model.surface_terms(s, user, w);
    match mode {
        PhaseMode::Bits(b) => {
            model.surface_optimal_phases(s, user, theta);
            let sum = w
                .iter()
                .zip(theta.iter())
                .map(|(wn, &t)| wn * C64::from_polar(1.0, quantise_phase(t, b)))
                .sum();
            (sum, tau)
        }
        _ => (C64::new(l1_norm(w), 0.0), tau),
    }
}

/// Per AP and cell, the direct link's and the other surfaces' part of the gain: the same for
/// every candidate pose of the moving surface, so computed once (stopped by a cancel). With
/// `by_rows` (continuous phases, `coherent` surfaces) a row at a time
/// ([`ChannelModel::closed_form_row`]), else cell by cell.
fn shared(
    base: &Scenario,
    grid: &Grid,
    occupied: &[bool],
    moving: usize,
    mode: PhaseMode,
    by_rows: bool,
    progress: &Progress,
) -> Shared {
    let height = base.mru.antenna_height_m;
    let lengths: Vec<usize> = base.surfaces().iter().map(|s| s.subsurfaces()).collect();
    let max_n = lengths.iter().copied().max().unwrap_or(0);
    let per_ap: Vec<(Vec<C64>, Vec<f64>)> = (0..base.access_points().len())
        .map(|ap| {
            let model = ChannelModel::for_ap(base, ap);
            if by_rows {
                let mut field = vec![C64::new(0.0, 0.0); grid.cells()];
                let mut tau = vec![0.0; grid.cells()];
                field
                    .par_chunks_mut(grid.ny)
                    .zip(tau.par_chunks_mut(grid.ny))
                    .zip(occupied.par_chunks(grid.ny))
                    .enumerate()
                    .for_each_init(ClosedFormRow::default, |row, (i, ((field, tau), skip))| {
                        if progress.is_cancelled() {
                            return;
                        }
                        let x = grid.x_min + i as f64 * grid.resolution_m;
                        let terms = RowTerms::AllBut(moving);
                        model.closed_form_row(
                            terms,
                            x,
                            grid.y_min,
                            grid.resolution_m,
                            height,
                            skip,
                            row,
                        );
                        for (f, &a) in field.iter_mut().zip(&row.amplitude) {
                            *f = C64::new(a, 0.0);
                        }
                        tau.copy_from_slice(&row.tau);
                    });
                return (field, tau);
            }
            (0..grid.cells())
                .into_par_iter()
                .map_init(
                    || (vec![C64::new(0.0, 0.0); max_n], vec![0.0; max_n]),
                    |(w, theta), k| {
                        // Once cancelled, the remaining cells are skipped (the caller then
                        // returns Cancelled): a pass over a big floor plan takes a minute.
                        if occupied[k] || progress.is_cancelled() {
                            return (C64::new(0.0, 0.0), 0.0);
                        }
                        let (i, j) = grid.cell_of(k);
                        let [x, y] = grid.centre(i, j);
                        let user = [x, y, height];
                        let direct = model.direct(user);
                        let mut field = match mode {
                            PhaseMode::Bits(_) => direct.h,
                            _ => C64::new(direct.h.norm(), 0.0),
                        };
                        let mut tau = direct.tau;
                        for (s, &n) in lengths.iter().enumerate().filter(|(s, _)| *s != moving) {
                            let (part, tau_s) =
                                surface_part(&model, s, user, mode, &mut w[..n], &mut theta[..n]);
                            field += part;
                            tau += tau_s;
                        }
                        (field, tau)
                    },
                )
                .unzip()
        })
        .collect();
    let (field, tau) = per_ap.into_iter().unzip();
    Shared { field, tau }
}

/// Scratch of one worker scoring candidates: kept between candidates, so a candidate allocates
/// only its channel models.
struct Scratch {
    w: Vec<C64>,
    theta: Vec<f64>,
    row: ClosedFormRow,
    /// The candidate's map: best gain per cell in dB, NaN where occupied.
    values: Vec<f64>,
}

/// What every candidate pose of a moving IRS is evaluated on.
struct Floor<'a> {
    grid: &'a Grid,
    occupied: &'a [bool],
    /// The MRU's antenna height (m).
    height: f64,
    mode: PhaseMode,
    /// Rows at a time ([`shared`]) rather than cell by cell.
    by_rows: bool,
    /// The moving surface, in scenario order.
    moving: usize,
    shared: Shared,
}

/// One candidate's map values (dB, NaN where occupied) into `scratch.values`: the shared part
/// plus the moving surface's own terms, best over the APs.
fn candidate_values(
    floor: &Floor,
    models: &[ChannelModel],
    scratch: &mut Scratch,
    progress: &Progress,
) -> Result<(), Cancelled> {
    let Floor {
        grid,
        occupied,
        height,
        mode,
        by_rows,
        moving,
        ref shared,
    } = *floor;
    let Scratch {
        w,
        theta,
        row,
        values,
    } = scratch;
    if by_rows {
        let db_per_neper = 10.0 * std::f64::consts::LOG10_E;
        let rows = values.chunks_mut(grid.ny).zip(occupied.chunks(grid.ny));
        for (i, (values, skip)) in rows.enumerate() {
            if progress.is_cancelled() {
                return Err(Cancelled);
            }
            let x = grid.x_min + i as f64 * grid.resolution_m;
            let cells = i * grid.ny..(i + 1) * grid.ny;
            for (ap, model) in models.iter().enumerate() {
                let terms = RowTerms::Surface(moving);
                model.closed_form_row(terms, x, grid.y_min, grid.resolution_m, height, skip, row);
                let (field, tau) = (
                    &shared.field[ap][cells.clone()],
                    &shared.tau[ap][cells.clone()],
                );
                let own = row.amplitude.iter().zip(&row.tau);
                for (((value, f), t), (a, t_own)) in values.iter_mut().zip(field).zip(tau).zip(own)
                {
                    let gain = (f.re + a).powi(2) + t + t_own;
                    if ap == 0 || gain > *value {
                        *value = gain;
                    }
                }
            }
            crate::vecmath::ln_in_place(values);
            for (value, &occupied) in values.iter_mut().zip(skip) {
                *value = if occupied {
                    f64::NAN
                } else {
                    *value * db_per_neper
                };
            }
        }
        return Ok(());
    }
    for (cell, value) in values.iter_mut().enumerate() {
        if occupied[cell] {
            *value = f64::NAN;
            continue;
        }
        // One candidate on a big floor plan takes minutes: a cancel is honoured per cell (one
        // relaxed load).
        if progress.is_cancelled() {
            return Err(Cancelled);
        }
        let (i, j) = grid.cell_of(cell);
        let [x, y] = grid.centre(i, j);
        let user = [x, y, height];
        let mut best = f64::NEG_INFINITY;
        for (ap, model) in models.iter().enumerate() {
            let (part, tau_k) = surface_part(model, moving, user, mode, w, theta);
            let field = shared.field[ap][cell];
            let gain = match mode {
                PhaseMode::Bits(_) => (field + part).norm_sqr(),
                _ => (field.re + part.re).powi(2),
            } + shared.tau[ap][cell]
                + tau_k;
            best = best.max(gain);
        }
        *value = 10.0 * best.log10();
    }
    Ok(())
}

/// How an answer names scenarios and maps. Ids are hashes of documents, which the model does
/// not write: the answers crate does (`irs_answers::map::ContentIds`).
pub trait Naming: Sync {
    /// The id of a scenario.
    fn scenario_id(&self, scenario: &Scenario) -> String;
    /// The ids of many scenarios, which may share work (a floor plan's image, hashed once).
    fn scenario_ids(&self, scenarios: &[&Scenario]) -> Vec<String> {
        scenarios.iter().map(|s| self.scenario_id(s)).collect()
    }
    /// The id of the map a key defines.
    fn map_id(&self, key: &MapKey) -> String;
}

/// Checks a search, scores every candidate and ranks them (see [`candidates`] and
/// [`rank_candidates`]).
pub fn place(
    base: &Scenario,
    search: &Search,
    naming: &dyn Naming,
    progress: &Progress,
) -> Result<Placement, WorkError> {
    rank_candidates(base, search, candidates(base, search)?, naming, progress)
}

/// Scores the candidates [`candidates`] listed for `search` and ranks them. `progress` counts
/// cell evaluations; cancellation is checked once per cell.
pub fn rank_candidates(
    base: &Scenario,
    search: &Search,
    candidates: Vec<Candidate>,
    naming: &dyn Naming,
    progress: &Progress,
) -> Result<Placement, WorkError> {
    let mode = search.phases.unwrap_or(PhaseMode::Continuous);
    let grid = base.grid();
    let occupied = radiomap::occupancy(base, &grid);
    let valid: Vec<(usize, &Scenario)> = candidates
        .iter()
        .enumerate()
        .filter_map(|(k, c)| c.scenario.as_ref().ok().map(|s| (k, s)))
        .collect();
    let aps = base.access_points().len();
    progress.start(valid.len() * grid.cells() * aps);
    let height = base.mru.antenna_height_m;
    let scores: Vec<(usize, Option<f64>)> = match search.what {
        What::Irs => {
            // The row form needs the closed form (continuous phases) and one link budget per
            // surface (`coherent`): the moving surface stays `coherent` at every pose.
            let by_rows = mode == PhaseMode::Continuous
                && base
                    .surfaces()
                    .iter()
                    .all(|s| s.grouping == Grouping::Coherent);
            let moving = search.index;
            let floor = Floor {
                grid: &grid,
                occupied: &occupied,
                height,
                mode,
                by_rows,
                moving,
                shared: shared(base, &grid, &occupied, moving, mode, by_rows, progress),
            };
            if progress.is_cancelled() {
                return Err(Cancelled.into());
            }
            let n = base.surfaces()[moving].subsurfaces();
            valid
                .par_iter()
                .map_init(
                    || Scratch {
                        w: vec![C64::new(0.0, 0.0); n],
                        theta: vec![0.0; n],
                        row: ClosedFormRow::default(),
                        values: vec![f64::NAN; grid.cells()],
                    },
                    |scratch, &(k, scenario)| {
                        if progress.is_cancelled() {
                            return Err(Cancelled);
                        }
                        let models: Vec<ChannelModel> = (0..aps)
                            .map(|ap| ChannelModel::for_ap(scenario, ap))
                            .collect();
                        candidate_values(&floor, &models, scratch, progress)?;
                        progress.advance(grid.cells() * aps);
                        let score = score(&grid, &scratch.values, &occupied, &search.objective);
                        Ok((k, score))
                    },
                )
                .collect::<Result<_, Cancelled>>()?
        }
        What::Ap => valid
            .par_iter()
            .map(
                |&(k, scenario)| -> Result<(usize, Option<f64>), WorkError> {
                    if progress.is_cancelled() {
                        return Err(Cancelled.into());
                    }
                    let key = MapKey::gain("placement", scenario, mode)?;
                    let map =
                        radiomap::build(scenario, &key, naming.map_id(&key), &progress.child())?;
                    progress.advance(grid.cells() * aps);
                    Ok((
                        k,
                        score(&grid, &map.values, &map.occupied, &search.objective),
                    ))
                },
            )
            .collect::<Result<_, WorkError>>()?,
    };
    let mut scores = scores;
    rank(&mut scores, &search.objective);
    let scenario = |k: usize| {
        candidates[k]
            .scenario
            .as_ref()
            .expect("only valid candidates are scored")
    };
    // Ids hash each candidate's whole document, a share of the candidates per thread: the
    // floor plan's image a share has in common is hashed once (a candidate AP, written before
    // the image, still hashes its own, in parallel).
    let ranked_scenarios: Vec<&Scenario> = scores.iter().map(|&(k, _)| scenario(k)).collect();
    let share = ranked_scenarios
        .len()
        .div_ceil(rayon::current_num_threads())
        .max(1);
    let scenario_ids: Vec<Vec<String>> = ranked_scenarios
        .par_chunks(share)
        .map(|chunk| naming.scenario_ids(chunk))
        .collect();
    let ids: Vec<(String, String)> = scenario_ids
        .into_iter()
        .flatten()
        .zip(&ranked_scenarios)
        .map(|(scenario_id, scenario)| {
            let map_id = naming.map_id(&MapKey::gain(&scenario_id, scenario, mode)?);
            Ok((scenario_id, map_id))
        })
        .collect::<Result<_, FieldError>>()?;
    let mut ranked = Vec::with_capacity(scores.len());
    let mut scenarios = Vec::with_capacity(scores.len());
    for (rank, ((k, score), (scenario_id, map_id))) in scores.into_iter().zip(ids).enumerate() {
        let c = &candidates[k];
        ranked.push(Ranked {
            rank: rank + 1,
            center: c.center,
            normal: c.normal,
            score,
            scenario_id,
            map_id,
        });
        scenarios.push(scenario(k).clone());
    }
    let rejected = candidates
        .iter()
        .filter_map(|c| {
            c.scenario.as_ref().err().map(|e| Rejected {
                center: c.center,
                normal: c.normal,
                reason: e.to_string(),
            })
        })
        .collect();
    Ok(Placement {
        answer: PlacementAnswer {
            scenario_id: naming.scenario_id(base),
            what: search.what,
            index: search.index,
            map_kind: "gain",
            phases: mode,
            objective: search.objective,
            unit: search.objective.unit(),
            candidates: ranked,
            rejected,
        },
        scenarios,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::MAX_NAME_CHARS;

    #[test]
    fn candidates_are_named_after_their_parent_and_place() {
        let name = |parent, what, at| candidate_name(parent, what, at);
        assert_eq!(
            name(Some("warehouse"), What::Irs, [29.75, -5.5000000001, 1.8]),
            "warehouse @ IRS (29.75, -5.5)"
        );
        assert_eq!(
            name(Some("floor"), What::Ap, [-0.0001, 3.0, 2.25]),
            "floor @ AP (0, 3, 2.25)"
        );
        assert_eq!(name(None, What::Irs, [1.0, 2.0, 3.0]), "IRS (1, 2)");
        let long = "x".repeat(MAX_NAME_CHARS);
        let cut = name(Some(&long), What::Irs, [-123.456, 78.9, 0.0]);
        assert_eq!(cut.chars().count(), MAX_NAME_CHARS);
        assert!(cut.ends_with("xx… @ IRS (-123.456, 78.9)"), "{cut}");
        let fits = "y".repeat(MAX_NAME_CHARS - " @ IRS (1, 2)".len());
        assert_eq!(
            name(Some(&fits), What::Irs, [1.0, 2.0, 0.0])
                .chars()
                .count(),
            MAX_NAME_CHARS
        );
        assert!(!name(Some(&fits), What::Irs, [1.0, 2.0, 0.0]).contains('…'));
    }
}
