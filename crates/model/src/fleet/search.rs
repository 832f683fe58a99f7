//! One robot's route in space and time given the robots already fixed (docs/model.md §6.5):
//! first its route alone, driven without waiting, if every robot's requirement holds along it;
//! otherwise A* over (cell, step), waiting allowed, which finds the earliest arrival within the
//! horizon whenever one exists.
//!
//! After the last fixed robot arrives the world no longer changes, so every step beyond it is
//! one layer of the search: the states stay within cells × (last arrival + 2).

use super::{Instant, MAX_EXPANSIONS, MAX_PLAN_EXPANSIONS, PlannedBy, Requirements};
use super::{Party, RobotInstant, RobotPlan};
use super::{Unserved, Violation};
use crate::planner::CellGraph;
use crate::radiomap::Unit;
use crate::radiomap::{Cancelled, Progress};
use crate::scenario::Grid;
use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};

/// No second cell held.
const NONE: u32 = u32::MAX;

/// A robot's route step by step: the cell it is measured at, and the other cell it holds
/// while moving between the two ([`NONE`] when it holds one).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Track {
    pub at: Vec<u32>,
    pub also: Vec<u32>,
}

impl Track {
    /// A track that holds one cell at every step (a given route sampled).
    pub fn still(at: Vec<u32>) -> Track {
        let also = vec![NONE; at.len()];
        Track { at, also }
    }

    /// Where it is at step k: after its arrival, at its goal.
    fn state(&self, k: usize) -> (u32, u32) {
        match self.at.get(k) {
            Some(&c) => (c, self.also[k]),
            None => (*self.at.last().expect("a track has a start"), NONE),
        }
    }

    /// Steps spent waiting in place (not the inner steps of a move).
    pub fn waited(&self) -> usize {
        (1..self.at.len())
            .filter(|&k| self.at[k] == self.at[k - 1] && self.also[k] == NONE)
            .count()
    }

    /// The route's length in cells (1 a straight step, √2 a diagonal).
    pub fn distance_cells(&self, grid: &Grid) -> f64 {
        self.at
            .windows(2)
            .filter(|w| w[0] != w[1])
            .map(|w| {
                let (a, b) = (grid.cell_of(w[0] as usize), grid.cell_of(w[1] as usize));
                if a.0 != b.0 && a.1 != b.1 {
                    std::f64::consts::SQRT_2
                } else {
                    1.0
                }
            })
            .sum()
    }
}

/// A path of cells driven without waiting: each move takes `move_steps` (orthogonal, diagonal).
pub(crate) fn timed(grid: &Grid, cells: &[usize], move_steps: [usize; 2]) -> Track {
    let mut track = Track {
        at: vec![cells[0] as u32],
        also: vec![NONE],
    };
    for w in cells.windows(2) {
        let (a, b) = (grid.cell_of(w[0]), grid.cell_of(w[1]));
        let d = move_steps[usize::from(a.0 != b.0 && a.1 != b.1)];
        push_move(&mut track, w[0] as u32, w[1] as u32, d);
    }
    track
}

/// Where two tracks first meet, and how often.
pub(crate) struct Meeting {
    pub robots: [usize; 2],
    pub step: usize,
    pub cell: u32,
    pub steps: usize,
}

/// Every pair of `tracks` (robot, track) that share a cell at a step, or swap cells between
/// two, each tracked until both have arrived (a robot stays at its goal after).
pub(crate) fn meetings(tracks: &[(usize, &Track)]) -> Vec<Meeting> {
    let mut out = Vec::new();
    for (a, (ra, ta)) in tracks.iter().enumerate() {
        for (rb, tb) in &tracks[a + 1..] {
            let end = ta.at.len().max(tb.at.len());
            let mut first: Option<(usize, u32)> = None;
            let mut steps = 0;
            for k in 0..end {
                let (ca, cb) = (ta.state(k).0, tb.state(k).0);
                let (na, nb) = (ta.state(k + 1).0, tb.state(k + 1).0);
                let place = if ca == cb {
                    Some((k, ca))
                } else if na == cb && nb == ca {
                    Some((k, na))
                } else {
                    None
                };
                if let Some(p) = place {
                    first.get_or_insert(p);
                    steps += 1;
                }
            }
            if let Some((step, cell)) = first {
                out.push(Meeting {
                    robots: [*ra.min(rb), *ra.max(rb)],
                    step,
                    cell,
                    steps,
                });
            }
        }
    }
    out
}

/// Appends a move from `from` to `to` of `d` steps (a wait when they are equal).
fn push_move(track: &mut Track, from: u32, to: u32, d: usize) {
    for _ in 1..d {
        track.at.push(from);
        track.also.push(if from == to { NONE } else { to });
    }
    track.at.push(to);
    track.also.push(NONE);
}

/// The robots fixed so far and what the search needs about the floor.
pub(crate) struct World<'m> {
    graph: CellGraph<'m>,
    move_steps: [usize; 2],
    horizon: usize,
    /// (request index, route) in planning order.
    fixed: Vec<(usize, Track)>,
    /// The last fixed robot's arrival step.
    end: usize,
    /// Start cells of the robots still to plan.
    parked: Vec<u32>,
    /// Whether every requirement holds with the robot being planned at (cell, step layer).
    memo: HashMap<(u32, u32), bool>,
    /// Per step layer, which fixed robots meet their requirement among themselves: all of them
    /// unless a given route fails on its own, which a robot planned later is not blamed for.
    base: HashMap<u32, Vec<bool>>,
    /// States the plan may still expand ([`MAX_PLAN_EXPANSIONS`] at first).
    budget: usize,
    progress: &'m Progress,
    /// Cells of the scenario's SRUs taking part: no robot enters them.
    statics: Vec<u32>,
}

/// A state's key: its cell and step, every step after the last arrival being one.
type Key = (u32, u32);

/// Per state reached: its earliest step and the state it came from (cell, step).
type Reached = HashMap<Key, (usize, Option<(u32, usize)>)>;

impl<'m> World<'m> {
    pub fn new(
        graph: CellGraph<'m>,
        move_steps: [usize; 2],
        horizon: usize,
        progress: &'m Progress,
        statics: Vec<u32>,
    ) -> World<'m> {
        World {
            graph,
            move_steps,
            horizon,
            fixed: Vec::new(),
            end: 0,
            parked: Vec::new(),
            memo: HashMap::new(),
            base: HashMap::new(),
            budget: MAX_PLAN_EXPANSIONS,
            progress,
            statics,
        }
    }

    pub fn fix(&mut self, robot: usize, track: Track) {
        self.end = self.end.max(track.at.len() - 1);
        self.fixed.push((robot, track));
    }

    fn layer(&self, k: usize) -> u32 {
        k.min(self.end + 1) as u32
    }

    /// Whether robot `r`, at `cell` (holding `also` too) at step `k`, shares no cell with a
    /// fixed or parked robot and leaves every requirement met, its own included.
    fn allowed(
        &mut self,
        req: &mut Requirements,
        r: usize,
        cell: u32,
        also: u32,
        k: usize,
    ) -> bool {
        let mine = [cell, also];
        let taken = |c: u32| c != NONE && mine.contains(&c);
        if self.parked.iter().chain(&self.statics).any(|&p| taken(p)) {
            return false;
        }
        if self.fixed.iter().any(|(_, t)| {
            let (a, b) = t.state(k);
            taken(a) || taken(b)
        }) {
            return false;
        }
        let key = (cell, self.layer(k));
        if let Some(&ok) = self.memo.get(&key) {
            return ok;
        }
        let ok = self.requirements_hold(req, r, cell as usize, k);
        self.memo.insert(key, ok);
        ok
    }

    /// Whether robot `r` at `cell` at step k meets its requirement and every fixed robot that
    /// met its own without `r` still does.
    fn requirements_hold(
        &mut self,
        req: &mut Requirements,
        r: usize,
        cell: usize,
        k: usize,
    ) -> bool {
        let own = req.link(cell);
        let link = &req.store[own];
        if link.unreached() && req.sharing.is_none() {
            // No surface reaches it: it takes no part in their choice, so the fixed robots
            // get what they had (met, as they were fixed), and it gets |h̃|² + τ.
            let (gains, need) = (
                req.joint.configure(&[link], &[1.0]).gains,
                req.need[r][link.ap],
            );
            return gains[0] >= need * (1.0 - super::MET_TOLERANCE);
        }
        let mut robots: Vec<usize> = self.fixed.iter().map(|(f, _)| *f).collect();
        let mut cells: Vec<usize> = self
            .fixed
            .iter()
            .map(|(_, t)| t.state(k).0 as usize)
            .collect();
        let layer = self.layer(k);
        // Parties: the fixed robots, then (with `access`) the scenario's SRUs; with this
        // robot, it comes between the two.
        let base = self
            .base
            .entry(layer)
            .or_insert_with(|| req.instant(&robots, &cells).met)
            .clone();
        let fixed = robots.len();
        robots.push(r);
        cells.push(cell);
        let met = req.instant(&robots, &cells).met;
        let kept = |(&was, &is): (&bool, &bool)| !was || is;
        met[fixed]
            && base[..fixed].iter().zip(&met[..fixed]).all(kept)
            && base[fixed..].iter().zip(&met[fixed + 1..]).all(kept)
    }

    /// True when a fixed robot goes from `to` to `from` while this one goes from `from` to
    /// `to` between steps k and k + 1.
    fn swaps(&self, from: u32, to: u32, k: usize) -> bool {
        from != to
            && self
                .fixed
                .iter()
                .any(|(_, t)| t.state(k).0 == to && t.state(k + 1).0 == from)
    }

    /// Whether `track` holds from its start until the world stops changing.
    fn holds(&mut self, req: &mut Requirements, r: usize, track: &Track) -> bool {
        let last = (track.at.len() - 1).max(self.end + 1);
        (0..=last).all(|k| {
            let (c, a) = track.state(k);
            self.allowed(req, r, c, a, k) && !self.swaps(c, track.state(k + 1).0, k)
        })
    }

    /// Robot `r`'s route from `start` to `goal` at `threshold`: `alone` (its route on its own)
    /// if it holds, else the earliest arrival in space and time; `Err` once cancelled.
    #[allow(clippy::too_many_arguments)]
    pub fn plan(
        &mut self,
        req: &mut Requirements,
        r: usize,
        threshold: f64,
        alone: &Track,
        start: usize,
        goal: usize,
        parked: &[usize],
    ) -> Result<Result<(Track, PlannedBy), Unserved>, Cancelled> {
        self.memo.clear();
        self.base.clear();
        self.parked = parked
            .iter()
            .map(|&c| c as u32)
            .filter(|&c| c != start as u32)
            .collect();
        if self.holds(req, r, alone) {
            return Ok(Ok((alone.clone(), PlannedBy::Alone)));
        }
        let (start, goal) = (start as u32, goal as u32);
        if !self.allowed(req, r, start, NONE, 0) {
            return Ok(Err(Unserved::StartConflict));
        }
        let limit = MAX_EXPANSIONS.min(self.budget);
        let grid = *self.graph.grid;
        let [orth, diag] = self.move_steps;
        let (gi, gj) = grid.cell_of(goal as usize);
        let heuristic = |c: u32| {
            let (i, j) = grid.cell_of(c as usize);
            let (di, dj) = (i.abs_diff(gi), j.abs_diff(gj));
            let (lo, hi) = (di.min(dj), di.max(dj));
            orth * (hi - lo) + diag.min(2 * orth) * lo
        };
        // (f, Reverse(k), cell): the smallest f first, then the latest step.
        let mut open = BinaryHeap::new();
        let mut reached: Reached = HashMap::new();
        let mut closed: HashSet<Key> = HashSet::new();
        open.push(Reverse((heuristic(start), Reverse(0usize), start)));
        reached.insert((start, 0), (0, None));
        let mut expanded = 0;
        let mut neighbours = Vec::with_capacity(8);
        while let Some(Reverse((_, Reverse(k), cell))) = open.pop() {
            let key = (cell, self.layer(k));
            if !closed.insert(key) {
                continue;
            }
            expanded += 1;
            if expanded % 4096 == 0 && self.progress.is_cancelled() {
                return Err(Cancelled);
            }
            if expanded > limit {
                self.budget -= limit;
                return Ok(Err(Unserved::Budget { expanded: limit }));
            }
            if cell == goal && self.stays(req, r, goal, k) {
                self.budget -= expanded;
                return Ok(Ok((self.track(&reached, key, k), PlannedBy::SpaceTime)));
            }
            let mut push = |world: &World, to: u32, at: usize| {
                let key = (to, world.layer(at));
                if closed.contains(&key) || reached.get(&key).is_some_and(|&(s, _)| s <= at) {
                    return;
                }
                reached.insert(key, (at, Some((cell, k))));
                open.push(Reverse((at + heuristic(to), Reverse(at), to)));
            };
            // Waiting helps only while the world still changes.
            if k <= self.end && k < self.horizon && self.allowed(req, r, cell, NONE, k + 1) {
                push(self, cell, k + 1);
            }
            neighbours.clear();
            self.graph
                .for_each_neighbour(cell as usize, |n, _, direction| {
                    neighbours.push((n as u32, direction >= 4));
                });
            for &(n, diagonal) in &neighbours {
                let d = self.move_steps[usize::from(diagonal)];
                if k + d > self.horizon || !self.graph.is_feasible(n as usize, threshold) {
                    continue;
                }
                let ok = (1..d).all(|t| self.allowed(req, r, cell, n, k + t))
                    && self.allowed(req, r, n, NONE, k + d)
                    && (d > 1 || !self.swaps(cell, n, k));
                if ok {
                    push(self, n, k + d);
                }
            }
        }
        self.budget -= expanded;
        Ok(Err(Unserved::Horizon {
            horizon_steps: self.horizon,
        }))
    }

    /// Whether the robot can stay at `goal` from step k until the world stops changing.
    fn stays(&mut self, req: &mut Requirements, r: usize, goal: u32, k: usize) -> bool {
        (k + 1..=self.end + 1).all(|t| self.allowed(req, r, goal, NONE, t))
    }

    /// The track ending at state `key` (step `k`), rebuilt from the search's parents.
    fn track(&self, reached: &Reached, key: Key, k: usize) -> Track {
        let mut states = vec![(key.0, k)];
        let mut at = key;
        while let Some(&(_, Some((cell, step)))) = reached.get(&at) {
            states.push((cell, step));
            at = (cell, self.layer(step));
        }
        states.reverse();
        let mut track = Track {
            at: vec![states[0].0],
            also: vec![NONE],
        };
        for w in states.windows(2) {
            push_move(&mut track, w[0].0, w[1].0, w[1].1 - w[0].1);
        }
        track
    }

    /// Every step from 0 to the last arrival, re-evaluated: what the IRSs held, what each
    /// robot got, and every requirement not met.
    pub fn timeline(
        &self,
        req: &mut Requirements,
        plans: &[RobotPlan],
        unit: Unit,
        dt_s: f64,
    ) -> (Vec<Instant>, Vec<Violation>) {
        let grid = req.map.grid;
        let lengths = req.joint.surface_lengths();
        let robots: Vec<usize> = self.fixed.iter().map(|(r, _)| *r).collect();
        let mut timeline = Vec::with_capacity(self.end + 1);
        let mut violations = Vec::new();
        for k in 0..=self.end {
            let time_s = k as f64 * dt_s;
            let cells: Vec<usize> = self
                .fixed
                .iter()
                .map(|(_, t)| t.state(k).0 as usize)
                .collect();
            let super::Evaluated {
                config,
                met,
                shares,
            } = req.instant(&robots, &cells);
            let statics: &[super::Static] = req.sharing.as_ref().map_or(&[], |s| &s.statics);
            let mut states = vec![None; plans.len()];
            let mut srus = Vec::with_capacity(statics.len());
            for slot in 0..met.len() {
                let (party, x, y, cell, required) = match robots.get(slot) {
                    Some(&r) => {
                        let cell = cells[slot];
                        let (i, j) = grid.cell_of(cell);
                        let [x, y] = grid.centre(i, j);
                        (Party::Robot(r), x, y, cell, plans[r].threshold)
                    }
                    None => {
                        let sru = &statics[slot - robots.len()];
                        let [x, y, _] = sru.position;
                        let required = match unit {
                            Unit::Mbps => {
                                sru.rate
                                    * req.map.links[sru.link.ap].bandwidth_mhz.unwrap_or(f64::NAN)
                            }
                            _ => sru.rate,
                        };
                        (Party::Sru(slot - robots.len()), x, y, sru.cell, required)
                    }
                };
                let (i, j) = grid.cell_of(cell);
                let ap = match party {
                    Party::Robot(_) => req.store[req.links[cell] as usize].ap,
                    Party::Sru(k) => statics[k].link.ap,
                };
                let gain_db = 10.0 * config.gains[slot].log10();
                let value = if unit == Unit::GainDb {
                    gain_db
                } else {
                    req.map.links[ap].convert_gain_db(unit, gain_db)
                };
                let state = RobotInstant {
                    x,
                    y,
                    i,
                    j,
                    ap,
                    value,
                    met: met[slot],
                    power_share: shares[slot].map(|(f, _)| f),
                    decoded: shares[slot].and_then(|(_, place)| place),
                };
                match party {
                    Party::Robot(r) => states[r] = Some(state),
                    Party::Sru(_) => srus.push(state),
                }
                if !met[slot] {
                    violations.push(Violation {
                        party,
                        step: k,
                        time_s,
                        x,
                        y,
                        value,
                        required,
                    });
                }
            }
            let party = |slot: usize| match robots.get(slot) {
                Some(&r) => Party::Robot(r),
                None => Party::Sru(slot - robots.len()),
            };
            timeline.push(Instant {
                step: k,
                time_s,
                served: config.served.iter().map(|s| s.map(party)).collect(),
                phases: crate::radiomap::per_surface(
                    config.phases.clone(),
                    lengths.iter().copied(),
                )
                .into_vec(),
                robots: states,
                srus,
            });
        }
        (timeline, violations)
    }
}
