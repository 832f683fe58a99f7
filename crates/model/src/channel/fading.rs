//! Instantaneous channels drawn from the per-element Rician model (paper eqs. 1–4): the Monte
//! Carlo reference for Lemma 1 and for the exact expected rates, independent of the closed
//! forms of the parent module.

use super::{C64, ChannelModel, IrsModel, LinkBudget, P3};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

impl ChannelModel {
    /// Draws instantaneous channels c_u = h_u + Σ_s Σ_e θ_{n(e)} r_{u,e} g_e for several users
    /// at once from the per-element Rician model (paper eqs. 1–4), independent of the closed
    /// form above: the Monte Carlo reference for Lemma 1 and for the exact expected rates
    /// (paper Fig. 10). Each surface's AP–IRS channel g is common to all users of a draw, as it
    /// is physically. `theta` is the concatenated phase vector (length N) or `None` for the
    /// no-IRS benchmark; `visit` is called once per draw with one coefficient per user.
    pub fn sample_channels<R: Rng + ?Sized>(
        &self,
        users: &[[f64; 3]],
        theta: Option<&[f64]>,
        draws: usize,
        rng: &mut R,
        mut visit: impl FnMut(&[C64]),
    ) {
        /// One reflecting element: its surface, its sub-surface in the concatenated θ, and the
        /// scattering point carrying its LoS phase (every element of a coherent sub-surface
        /// sits at the sub-surface centre).
        struct Element {
            surface: usize,
            sub: usize,
            point: usize,
        }
        struct UserStats {
            h_los: C64,
            h_scatter: f64,
            /// Per element: LoS IRS→user coefficient √(L K/(K+1)) e^{−j2π d/λ} (zero for the
            /// elements of surfaces the user is not in front of).
            r_los: Vec<C64>,
            /// Per surface: the scattered amplitude, or `None` when the user is behind it.
            r_scatter: Vec<Option<f64>>,
        }
        let surfaces: &[IrsModel] = if theta.is_some() { &self.surfaces } else { &[] };
        let rot: Vec<C64> = theta.map_or(Vec::new(), |t| {
            t.iter().map(|&p| C64::from_polar(1.0, p)).collect()
        });
        let elements: Vec<Element> = surfaces
            .iter()
            .enumerate()
            .flat_map(|(s, irs)| {
                let n_bar = irs.elements / irs.subsurfaces;
                (0..irs.elements).map(move |e| Element {
                    surface: s,
                    sub: irs.offset + e / n_bar,
                    point: if irs.per_sub == 1 { e / n_bar } else { e },
                })
            })
            .collect();
        let stats: Vec<UserStats> = users
            .iter()
            .map(|u| {
                let q = P3::from(*u);
                let direct = self.link_seen(&self.ap_sight, &q);
                let links: Vec<Option<LinkBudget>> = surfaces
                    .iter()
                    .map(|irs| self.irs_user_link(irs, &q))
                    .collect();
                UserStats {
                    h_los: self.los_phase((q - self.ap).norm()) * direct.los_amplitude(),
                    h_scatter: direct.scattered_power().sqrt(),
                    r_los: elements
                        .iter()
                        .map(|el| {
                            links[el.surface].map_or(C64::new(0.0, 0.0), |link| {
                                let p = surfaces[el.surface].points[el.point];
                                self.los_phase((q - p).norm()) * link.los_amplitude()
                            })
                        })
                        .collect(),
                    r_scatter: links
                        .iter()
                        .map(|l| l.map(|l| l.scattered_power().sqrt()))
                        .collect(),
                }
            })
            .collect();
        let g_los: Vec<C64> = elements
            .iter()
            .map(|el| {
                let irs = &surfaces[el.surface];
                self.los_phase(irs.ap_distance[el.point]) * irs.ap_link.los_amplitude()
            })
            .collect();
        let g_scatter: Vec<f64> = surfaces
            .iter()
            .map(|irs| irs.ap_link.scattered_power().sqrt())
            .collect();
        let cn = |rng: &mut R| -> C64 {
            let re: f64 = StandardNormal.sample(rng);
            let im: f64 = StandardNormal.sample(rng);
            C64::new(re, im) * std::f64::consts::FRAC_1_SQRT_2
        };
        let mut g = vec![C64::new(0.0, 0.0); g_los.len()];
        let mut c = vec![C64::new(0.0, 0.0); users.len()];
        for _ in 0..draws {
            for ((ge, gl), el) in g.iter_mut().zip(&g_los).zip(&elements) {
                *ge = gl + cn(rng) * g_scatter[el.surface];
            }
            for (cu, s) in c.iter_mut().zip(&stats) {
                *cu = s.h_los + cn(rng) * s.h_scatter;
                let mut reflected = C64::new(0.0, 0.0);
                for ((el, ge), rl) in elements.iter().zip(&g).zip(&s.r_los) {
                    if let Some(scatter) = s.r_scatter[el.surface] {
                        let r = rl + cn(rng) * scatter;
                        reflected += rot[el.sub] * r * ge;
                    }
                }
                *cu += reflected;
            }
            visit(&c);
        }
    }
}
