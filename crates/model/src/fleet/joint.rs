//! One instant of a fleet (docs/model.md §6.5): every robot's channel through its serving AP,
//! the phase vector each IRS holds (one for every robot and every AP: a surface reflects all
//! of them at once), and the gain each robot then gets.
//!
//! The policy, "largest deficit first": surfaces are configured one after the other in
//! scenario order. Surface s goes to the robot it can reach (a non-zero cascaded coefficient)
//! whose requirement is furthest from met by what it already has (its direct link, the
//! surfaces configured before s, and every scattered part), measured as the ratio
//! required / current; its phases are the ones that add its coefficients in phase with that
//! robot's current sum (eq. 11 when the surface is the first to serve it), quantised for
//! `bits`. Ties go to the robot of higher priority (lower index). With one robot every surface
//! serves it and its gain is eq. 12's: the single-robot map.

use crate::channel::{C64, ChannelModel};
use crate::phases::{PhaseMode, quantise_phase};
use std::f64::consts::TAU;
use std::sync::Arc;

/// A robot's channel at one cell through its serving AP: λ(θ) = |h̃ + w̃ᵀe^{jθ}|² + τ.
#[derive(Debug, Clone)]
pub(crate) struct Link {
    /// The serving AP (an index into the scenario's APs).
    pub ap: usize,
    h: C64,
    tau: f64,
    /// w̃, every surface's coefficients one after the other (N).
    w: Vec<C64>,
    /// Per surface: whether it reaches this cell at all (‖w̃_s‖₁ > 0).
    reach: Vec<bool>,
}

impl Link {
    /// True when no surface reaches the cell: the robot's gain is |h̃|² + τ whatever the
    /// surfaces hold, and it never takes part in their choice.
    pub fn unreached(&self) -> bool {
        !self.reach.iter().any(|&r| r)
    }
}

/// The channel models a fleet instant needs: one per AP, the surfaces' layout, the phase mode.
#[derive(Debug, Clone)]
pub(crate) struct JointChannel {
    models: Vec<Arc<ChannelModel>>,
    /// H₀ (m), the robots' antenna height.
    height_m: f64,
    mode: PhaseMode,
    /// (offset, N_s) of each surface in the concatenated vectors.
    surfaces: Vec<(usize, usize)>,
}

/// What the surfaces hold at one instant and what every robot gets.
#[derive(Debug, Clone, PartialEq)]
pub struct Configuration {
    /// Per surface, the robot it serves (an index into the instant's robots); `None` when it
    /// reaches none of them (its phases are then 0).
    pub served: Vec<Option<usize>>,
    /// θ, every surface's phases concatenated (N), in [0, 2π).
    pub phases: Vec<f64>,
    /// λ per robot (linear).
    pub gains: Vec<f64>,
}

impl JointChannel {
    pub fn new(models: Vec<Arc<ChannelModel>>, height_m: f64, mode: PhaseMode) -> JointChannel {
        let mut surfaces = Vec::new();
        let mut offset = 0;
        for n in models[0].surface_lengths() {
            surfaces.push((offset, n));
            offset += n;
        }
        JointChannel {
            models,
            height_m,
            mode,
            surfaces,
        }
    }

    /// N, the length of θ.
    pub fn subsurfaces(&self) -> usize {
        self.surfaces.iter().map(|&(_, n)| n).sum()
    }

    /// N_s of each surface.
    pub fn surface_lengths(&self) -> Vec<usize> {
        self.surfaces.iter().map(|&(_, n)| n).collect()
    }

    /// The channel at point (x, y), at the robots' antenna height, through AP `ap`.
    pub fn link(&self, ap: usize, [x, y]: [f64; 2]) -> Link {
        self.link_at(ap, [x, y, self.height_m])
    }

    /// The channel at an antenna at `position` (x, y, z) through AP `ap`.
    pub fn link_at(&self, ap: usize, position: [f64; 3]) -> Link {
        let model = &self.models[ap];
        let mut w = vec![C64::new(0.0, 0.0); model.subsurfaces()];
        let with_irs = self.mode != PhaseMode::None;
        let direct = model.evaluate(position, with_irs, &mut w);
        let reach = self
            .surfaces
            .iter()
            .map(|&(o, n)| w[o..o + n].iter().any(|c| c.norm_sqr() > 0.0))
            .collect();
        Link {
            ap,
            h: direct.h,
            tau: direct.tau,
            w,
            reach,
        }
    }

    /// The surfaces' configuration by the largest-deficit policy (module docs) for robots with
    /// channels `links` and required gains `need` (linear, one per robot).
    pub fn configure(&self, links: &[&Link], need: &[f64]) -> Configuration {
        let mut sums: Vec<C64> = links.iter().map(|l| l.h).collect();
        let mut phases = vec![0.0; self.subsurfaces()];
        let mut served = Vec::with_capacity(self.surfaces.len());
        for (s, &(offset, n)) in self.surfaces.iter().enumerate() {
            let mut choice: Option<(usize, f64)> = None;
            for (r, link) in links.iter().enumerate() {
                if !link.reach[s] {
                    continue;
                }
                let deficit = need[r] / (sums[r].norm_sqr() + link.tau);
                if choice.is_none_or(|(_, best)| deficit > best) {
                    choice = Some((r, deficit));
                }
            }
            served.push(choice.map(|(r, _)| r));
            let theta = &mut phases[offset..offset + n];
            if let Some((r, _)) = choice {
                let target = if sums[r].norm_sqr() > 0.0 {
                    sums[r].arg()
                } else {
                    0.0
                };
                for (t, wn) in theta.iter_mut().zip(&links[r].w[offset..offset + n]) {
                    let angle = if wn.norm_sqr() > 0.0 { wn.arg() } else { 0.0 };
                    *t = (target - angle).rem_euclid(TAU);
                    if let PhaseMode::Bits(b) = self.mode {
                        *t = quantise_phase(*t, b);
                    }
                }
            }
            let rotations: Vec<C64> = theta.iter().map(|&t| C64::from_polar(1.0, t)).collect();
            for (sum, link) in sums.iter_mut().zip(links) {
                if link.reach[s] {
                    *sum += link.w[offset..offset + n]
                        .iter()
                        .zip(&rotations)
                        .map(|(w, e)| w * e)
                        .sum::<C64>();
                }
            }
        }
        let gains = sums
            .iter()
            .zip(links)
            .map(|(sum, l)| sum.norm_sqr() + l.tau)
            .collect();
        Configuration {
            served,
            phases,
            gains,
        }
    }
}
