//! The channel model of docs/model.md §2 and the paper's Section II-A: per user location it yields the
//! direct LoS coefficient h̃, the cascaded LoS coefficients w̃ ∈ C^N of the IRS sub-surfaces and
//! the scattered power τ, so that the expected channel power gain for phases θ is
//!
//! λ(θ) = |h̃ + w̃ᵀθ|² + τ            (paper eqs. 5–6, Lemma 1)
//!
//! with
//! * h̃ = √(L_AM K_AM/(K_AM+1)) · e^{−j2π d_AM/λ},
//! * w̃_n = √(L_AI K_AI/(K_AI+1)) √(L_IM K_IM/(K_IM+1)) · Σ_{elements of n} e^{−j2π(d_A,e + d_e,U)/λ},
//! * τ = L_AM/(K_AM+1) + L_AI L_IM (K_IM + K_AI + 1) M / ((K_AI+1)(K_IM+1)).
//!
//! With several IRSs the model generalises exactly: w̃ is the surfaces' vectors concatenated in
//! scenario order and τ sums the scattered power of every path, λ(θ) = |h̃ + Σ_s w̃_sᵀθ_s|² + τ.
//! Paths via two surfaces (IRS → IRS) are not modelled: each is a product of two path gains
//! over the already weak single-bounce ones.
//!
//! Choices the paper leaves open (also in docs/model.md):
//! * Path losses L_AI and L_IM use the distance to each IRS's centre, as the paper's scalar
//!   L_AI, L_IM(q) do; LoS *phases* use exact (spherical) distances to each sub-surface centre
//!   (`coherent`) or each element (`elements`).
//! * A link is LoS unless its segment passes through the interior of a box, a wall or the floor
//!   plan's occupied pixels (grazing is LoS; [`crate::geometry`]); the IRS links are tested
//!   from the IRS centre.
//! * The IRS reflects only into its front half-space: a user on or behind the surface's plane
//!   gets no IRS term at all (neither w̃ nor the scattered part of τ).

mod fading;
mod rows;

pub use rows::{ClosedFormRow, RowTerms};

use crate::geometry::{Obstructions, SightLines};
use crate::scenario::{Grouping, Irs, SPEED_OF_LIGHT, Scenario};
use nalgebra::{Complex, Vector3};
use std::f64::consts::TAU;

/// Complex baseband coefficient.
pub type C64 = Complex<f64>;
type P3 = Vector3<f64>;

/// Large-scale parameters of one link: path gain L (linear, < 1) and Rician factor K (0 if NLoS).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkBudget {
    /// Whether the link is line of sight (no obstruction's interior on its segment, §2).
    pub los: bool,
    /// L = 10^(−PL/10), linear, from the InF-SH path loss PL of [`path_loss_db`] (eqs. 41–42).
    pub path_gain: f64,
    /// K, linear: the scenario's κ on a LoS link, 0 on a NLoS one (no deterministic component).
    pub rician_k: f64,
}

impl LinkBudget {
    /// √(L K/(K+1)), the amplitude of the deterministic LoS component.
    #[inline]
    pub fn los_amplitude(&self) -> f64 {
        (self.path_gain * self.rician_k / (self.rician_k + 1.0)).sqrt()
    }
    /// L/(K+1), the power of the Rayleigh (NLoS) component.
    #[inline]
    pub fn scattered_power(&self) -> f64 {
        self.path_gain / (self.rician_k + 1.0)
    }
}

/// 3GPP TR 38.901 InF-SH path loss in dB (paper Section IV). `d` is clamped to ≥ 1 m.
/// LoS: 31.84 + 21.50 log10 d + 19 log10 f_c; NLoS: max(LoS, 32.4 + 23 log10 d + 20 log10 f_c).
pub fn path_loss_db(distance_m: f64, carrier_ghz: f64, los: bool) -> f64 {
    path_loss_db_with(distance_m, carrier_ghz.log10(), los)
}

/// [`path_loss_db`] with log₁₀ f_c given: a model computes it once, not per link.
fn path_loss_db_with(distance_m: f64, f: f64, los: bool) -> f64 {
    path_loss_db_at(distance_m.max(1.0).log10(), f, los)
}

/// The InF-SH law of [`path_loss_db`] at log₁₀ d (d already clamped) and log₁₀ f_c.
#[inline(always)]
fn path_loss_db_at(log10_d: f64, f: f64, los: bool) -> f64 {
    let pl_los = 31.84 + 21.50 * log10_d + 19.0 * f;
    if los {
        pl_los
    } else {
        pl_los.max(32.4 + 23.0 * log10_d + 20.0 * f)
    }
}

/// One IRS as the channel model sees it: its scattering points and the fixed AP–IRS link.
#[derive(Debug, Clone)]
struct IrsModel {
    centre: P3,
    normal: P3,
    /// Where this surface's sub-surfaces start in the concatenated vectors w̃ and θ.
    offset: usize,
    /// N_s, this surface's sub-surfaces.
    subsurfaces: usize,
    /// Scattering points: sub-surface centres (`coherent`) or elements (`elements`); the points
    /// of sub-surface n are `points[n·per_sub .. (n+1)·per_sub]`.
    points: Vec<P3>,
    per_sub: usize,
    /// How many elements each point stands for: N̄ (`coherent`) or 1 (`elements`).
    weight: f64,
    /// M_s, this surface's elements.
    elements: usize,
    /// d(AP, point) for every point.
    ap_distance: Vec<f64>,
    ap_link: LinkBudget,
    /// The floor's obstacles indexed by direction from the surface's centre, where every
    /// IRS–user link starts (geometry::SightLines).
    sight: SightLines,
    /// False when this AP is on or behind the surface's plane: the surface then reflects
    /// nothing of it (with several APs a surface may face only some of them).
    faces_ap: bool,
}

/// The deterministic part of the model for one scenario; cheap to share across threads.
#[derive(Debug, Clone)]
pub struct ChannelModel {
    wavelength_m: f64,
    /// log₁₀ f_c (GHz), the carrier's term of the path loss.
    carrier_log10: f64,
    kappa: f64,
    ap: P3,
    /// Boxes, walls and the floor plan: what blocks a link.
    obstructions: Obstructions,
    /// The same indexed by direction from the AP, where every direct link starts: a link
    /// evaluated on its own tests only the obstacles in its direction (geometry::SightLines);
    /// a gain map's rows use `Obstructions::blocks_row` instead.
    ap_sight: SightLines,
    /// The IRSs in scenario order; their sub-surfaces are numbered one after the other.
    surfaces: Vec<IrsModel>,
    /// N = Σ_s N_s.
    subsurfaces: usize,
}

/// (h̃, τ) of one location; w̃ is written into a caller's buffer so hot loops do not allocate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DirectAndScattered {
    /// h̃, the direct LoS coefficient.
    pub h: C64,
    /// τ, the total scattered power.
    pub tau: f64,
}

/// The continuous closed form's inputs at one location ([`ChannelModel::closed_form_terms`]):
/// max_θ λ = (|h̃| + ‖w̃‖₁)² + τ (eq. 12).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClosedFormTerms {
    /// |h̃|, the direct link's LoS amplitude (0 when it is blocked).
    pub direct_amplitude: f64,
    /// τ, the total scattered power.
    pub tau: f64,
    /// ‖w̃‖₁ over every surface.
    pub l1: f64,
}

impl ChannelModel {
    /// Bytes the model holds on the heap, for cache weighing: the scattering points and their
    /// AP distances (6.4 MB at M = 200 000 elements), the boxes and the walls. A floor plan's
    /// raster is shared with the scenario (an `Arc`) and weighed with it.
    pub fn heap_bytes(&self) -> usize {
        let surfaces: usize = self
            .surfaces
            .iter()
            .map(|irs| {
                std::mem::size_of::<IrsModel>()
                    + irs.points.capacity() * std::mem::size_of::<P3>()
                    + irs.ap_distance.capacity() * std::mem::size_of::<f64>()
                    + irs.sight.heap_bytes()
            })
            .sum();
        std::mem::size_of::<ChannelModel>()
            + surfaces
            + self.obstructions.heap_bytes()
            + self.ap_sight.heap_bytes()
    }

    /// Builds the model of a validated scenario, for its first AP.
    pub fn new(scenario: &Scenario) -> ChannelModel {
        ChannelModel::for_ap(scenario, 0)
    }

    /// Builds the model of a validated scenario as AP `ap` (an index into
    /// [`Scenario::access_points`]) sees it: that AP's position and carrier, every IRS.
    pub fn for_ap(scenario: &Scenario, ap: usize) -> ChannelModel {
        let access_point = &scenario.access_points()[ap];
        let obstructions = scenario.obstructions();
        let mut model = ChannelModel {
            wavelength_m: SPEED_OF_LIGHT / (access_point.carrier_ghz * 1e9),
            carrier_log10: access_point.carrier_ghz.log10(),
            kappa: 10f64.powf(scenario.channel.rician_k_db / 10.0),
            ap: P3::from(access_point.position),
            ap_sight: SightLines::new(&obstructions, access_point.position),
            obstructions,
            surfaces: Vec::new(),
            subsurfaces: 0,
        };
        for irs in scenario.surfaces() {
            let surface = model.surface(irs, model.subsurfaces);
            model.subsurfaces += surface.subsurfaces;
            model.surfaces.push(surface);
        }
        model
    }

    /// The model of one IRS whose sub-surfaces start at `offset` in the concatenated vectors.
    fn surface(&self, irs: &Irs, offset: usize) -> IrsModel {
        let centre = P3::from(irs.center);
        let normal = P3::from(irs.normal).normalize();
        // Wall axes: horizontal u_h = ẑ × n (normalised), vertical u_v = n × u_h.
        let u_h = P3::z().cross(&normal).normalize();
        let u_v = normal.cross(&u_h);
        let pitch = irs.sub_pitch_m.expect("defaults resolved");
        let n_bar = irs.elements_per_sub;
        let mut points = Vec::new();
        let (per_sub, weight) = match irs.grouping {
            Grouping::Coherent => (1, n_bar as f64),
            Grouping::Elements => (n_bar, 1.0),
        };
        let element_pitch = irs.element_pitch_m.unwrap_or(0.0);
        for ix in 0..irs.nx_sub {
            for iz in 0..irs.nz_sub {
                let sub_centre = centre
                    + u_h * ((ix as f64 - (irs.nx_sub as f64 - 1.0) / 2.0) * pitch)
                    + u_v * ((iz as f64 - (irs.nz_sub as f64 - 1.0) / 2.0) * pitch);
                for k in 0..per_sub {
                    let along = (k as f64 - (per_sub as f64 - 1.0) / 2.0) * element_pitch;
                    points.push(sub_centre + u_h * along);
                }
            }
        }
        let ap_distance = points.iter().map(|p| (p - self.ap).norm()).collect();
        IrsModel {
            centre,
            normal,
            offset,
            subsurfaces: irs.subsurfaces(),
            points,
            per_sub,
            weight,
            elements: irs.elements(),
            ap_distance,
            ap_link: self.link_budget(&self.ap, &centre),
            sight: SightLines::new(&self.obstructions, irs.center),
            faces_ap: (self.ap - centre).dot(&normal) > 0.0,
        }
    }

    /// N, the length of w̃ and θ: every surface's sub-surfaces (0 without an IRS).
    pub fn subsurfaces(&self) -> usize {
        self.subsurfaces
    }

    /// N_s of each surface in scenario order: how θ splits into the surfaces' phase vectors.
    pub fn surface_lengths(&self) -> impl ExactSizeIterator<Item = usize> + '_ {
        self.surfaces.iter().map(|s| s.subsurfaces)
    }

    /// True when the segment between two points passes through an obstacle's interior.
    pub fn is_blocked(&self, a: [f64; 3], b: [f64; 3]) -> bool {
        self.obstructions.blocks(a, b)
    }

    fn link_budget(&self, a: &P3, b: &P3) -> LinkBudget {
        self.budget((a - b).norm(), !self.obstructions.blocks_segment(a, b))
    }

    /// [`ChannelModel::link_budget`] from an indexed source (the AP, an IRS centre) to `q`.
    fn link_seen(&self, sight: &SightLines, q: &P3) -> LinkBudget {
        self.budget(
            (q - sight.source()).norm(),
            !sight.blocks(&self.obstructions, q),
        )
    }

    fn budget(&self, distance_m: f64, los: bool) -> LinkBudget {
        let pl = path_loss_db_with(distance_m, self.carrier_log10, los);
        LinkBudget {
            los,
            // 10^(−PL/10) as one exponential (half the cost of `powf` in a map's inner loop).
            path_gain: (-pl * (std::f64::consts::LN_10 / 10.0)).exp(),
            rician_k: if los { self.kappa } else { 0.0 },
        }
    }

    /// e^{−j2π d/λ}, the LoS phase of a path of length d.
    #[inline]
    fn los_phase(&self, d: f64) -> C64 {
        let phi = -TAU * fraction_of_cycle(d / self.wavelength_m);
        let (s, c) = phi.sin_cos();
        C64::new(c, s)
    }

    /// The IRS–user link budget, or `None` when the surface cannot serve the user: the user is
    /// not in front of it, or the AP is not.
    fn irs_user_link(&self, irs: &IrsModel, user: &P3) -> Option<LinkBudget> {
        (irs.faces_ap && (user - irs.centre).dot(&irs.normal) > 0.0)
            .then(|| self.link_seen(&irs.sight, user))
    }

    /// Evaluates (h̃, w̃, τ) at `user`. `w` must have length N; it is filled with w̃, the
    /// surfaces' coefficients one after the other (zeros when `with_irs` is false or where a
    /// surface cannot serve this location). τ sums the direct link's scattered power and every
    /// surface's (Lemma 1 per surface; the scattered parts of different paths are independent).
    /// Without the IRS τ holds only the direct link's: the "no IRS" benchmark of Section IV.
    pub fn evaluate(&self, user: [f64; 3], with_irs: bool, w: &mut [C64]) -> DirectAndScattered {
        debug_assert_eq!(w.len(), self.subsurfaces());
        let mut total = self.direct(user);
        if !with_irs {
            w.iter_mut().for_each(|x| *x = C64::new(0.0, 0.0));
            return total;
        }
        for (s, irs) in self.surfaces.iter().enumerate() {
            total.tau +=
                self.surface_terms(s, user, &mut w[irs.offset..irs.offset + irs.subsurfaces]);
        }
        total
    }

    /// h̃ and the direct link's scattered power at `user`: λ without any IRS.
    pub fn direct(&self, user: [f64; 3]) -> DirectAndScattered {
        let q = P3::from(user);
        let direct = self.link_seen(&self.ap_sight, &q);
        DirectAndScattered {
            h: self.los_phase((q - self.ap).norm()) * direct.los_amplitude(),
            tau: direct.scattered_power(),
        }
    }

    /// |h̃|, τ and ‖w̃‖₁ at `user`: all that the continuous closed form (eq. 12) needs; |h̃| is
    /// the direct link's LoS amplitude, so its phase is never formed. With `coherent` grouping
    /// every sub-surface of a surface has the same |w̃_n| (the path losses use the surface
    /// centre's distances and N̄ elements add in phase), so a surface's ‖w̃_s‖₁ = N_s·|w̃_s,1|
    /// costs one link budget, not N_s phasors; with `elements` the element phasors are summed
    /// into `w` (length N) as [`Self::evaluate`] does.
    pub fn closed_form_terms(&self, user: [f64; 3], w: &mut [C64]) -> ClosedFormTerms {
        let q = P3::from(user);
        let direct = self.link_seen(&self.ap_sight, &q);
        let mut terms = ClosedFormTerms {
            direct_amplitude: direct.los_amplitude(),
            tau: direct.scattered_power(),
            l1: 0.0,
        };
        for (s, irs) in self.surfaces.iter().enumerate() {
            if irs.per_sub == 1 {
                if let Some(user_link) = self.irs_user_link(irs, &q) {
                    let amplitude =
                        irs.ap_link.los_amplitude() * user_link.los_amplitude() * irs.weight;
                    terms.l1 += irs.subsurfaces as f64 * amplitude;
                    terms.tau += Self::surface_scattered_power(irs, &user_link);
                }
            } else {
                let own = &mut w[irs.offset..irs.offset + irs.subsurfaces];
                terms.tau += self.surface_terms(s, user, own);
                terms.l1 += crate::numerics::l1_norm(own);
            }
        }
        terms
    }

    /// Lemma 1 for one surface: E|x3|² + E|x4|² + E|x5|² = L_AI L_IM (K_IM + K_AI + 1) M /
    /// ((K_AI+1)(K_IM+1)), the power its scattered paths add at a user it serves.
    fn surface_scattered_power(irs: &IrsModel, user_link: &LinkBudget) -> f64 {
        let (ka, ku) = (irs.ap_link.rician_k, user_link.rician_k);
        irs.ap_link.path_gain * user_link.path_gain * (ku + ka + 1.0) * irs.elements as f64
            / ((ka + 1.0) * (ku + 1.0))
    }

    /// Surface `s`'s part of the channel at `user`: fills `w` (length N_s) with its w̃_s and
    /// returns its scattered power τ_s (zeros when it cannot serve the user), so that
    /// λ(θ) = |h̃ + Σ_s w̃_sᵀθ_s|² + τ_direct + Σ_s τ_s.
    pub fn surface_terms(&self, s: usize, user: [f64; 3], w: &mut [C64]) -> f64 {
        let irs = &self.surfaces[s];
        debug_assert_eq!(w.len(), irs.subsurfaces);
        w.iter_mut().for_each(|x| *x = C64::new(0.0, 0.0));
        let q = P3::from(user);
        let Some(user_link) = self.irs_user_link(irs, &q) else {
            return 0.0;
        };
        let amplitude = irs.ap_link.los_amplitude() * user_link.los_amplitude() * irs.weight;
        if amplitude > 0.0 {
            for (n, wn) in w.iter_mut().enumerate() {
                let range = n * irs.per_sub..(n + 1) * irs.per_sub;
                let mut sum = C64::new(0.0, 0.0);
                for (p, d_ap) in irs.points[range.clone()]
                    .iter()
                    .zip(&irs.ap_distance[range])
                {
                    sum += self.los_phase(d_ap + (q - p).norm());
                }
                *wn = sum * amplitude;
            }
        }
        Self::surface_scattered_power(irs, &user_link)
    }

    /// ∠h̃ at `q` as eq. 11 uses it: 0 where the direct link is NLoS (h̃ = 0).
    fn direct_angle(&self, q: &P3) -> f64 {
        if self.link_seen(&self.ap_sight, q).los {
            -TAU * fraction_of_cycle((q - self.ap).norm() / self.wavelength_m)
        } else {
            0.0
        }
    }

    /// θ*_n = ∠h̃ − ∠w̃_n (paper eq. 11) at `user`, in [0, 2π), for every sub-surface of every
    /// surface (`out` has length N). With `coherent` grouping w̃_n is a positive amplitude times
    /// e^{−j2π(d_A,n + d_n,U)/λ}, so its angle follows from the two distances without any
    /// trigonometry; with `elements` it is the angle of the element sum. Where a term vanishes
    /// (an NLoS link, a user behind the IRS) its angle is taken as 0: every θ is then optimal.
    pub fn optimal_phases(&self, user: [f64; 3], out: &mut [f64]) {
        debug_assert_eq!(out.len(), self.subsurfaces());
        let q = P3::from(user);
        let h_angle = self.direct_angle(&q);
        for irs in &self.surfaces {
            self.surface_phases(
                irs,
                &q,
                h_angle,
                &mut out[irs.offset..irs.offset + irs.subsurfaces],
            );
        }
    }

    /// θ* of eq. 11 for surface `s` alone (`out` has length N_s): its slice of
    /// [`ChannelModel::optimal_phases`].
    pub fn surface_optimal_phases(&self, s: usize, user: [f64; 3], out: &mut [f64]) {
        let q = P3::from(user);
        self.surface_phases(&self.surfaces[s], &q, self.direct_angle(&q), out);
    }

    fn surface_phases(&self, irs: &IrsModel, q: &P3, h_angle: f64, out: &mut [f64]) {
        let angle_of_distance = |d: f64| -TAU * fraction_of_cycle(d / self.wavelength_m);
        let cascade_los = self
            .irs_user_link(irs, q)
            .is_some_and(|l| l.los && irs.ap_link.los);
        for (n, theta) in out.iter_mut().enumerate() {
            let w_angle = if !cascade_los {
                0.0
            } else if irs.per_sub == 1 {
                angle_of_distance(irs.ap_distance[n] + (q - irs.points[n]).norm())
            } else {
                let range = n * irs.per_sub..(n + 1) * irs.per_sub;
                let sum: C64 = irs.points[range.clone()]
                    .iter()
                    .zip(&irs.ap_distance[range])
                    .map(|(p, d_ap)| self.los_phase(d_ap + (q - p).norm()))
                    .sum();
                if sum.norm() > 0.0 { sum.arg() } else { 0.0 }
            };
            *theta = wrap_angle(h_angle - w_angle);
        }
    }
}

/// λ(θ) = |h̃ + Σ_n w̃_n e^{jθ_n}|² + τ (paper eq. 6) for an explicit phase vector.
pub fn expected_gain(direct: &DirectAndScattered, w: &[C64], theta: &[f64]) -> f64 {
    let mut sum = direct.h;
    for (wn, &t) in w.iter().zip(theta) {
        sum += wn * C64::from_polar(1.0, t);
    }
    sum.norm_sqr() + direct.tau
}

/// The fractional part of x ≥ 0, a distance in wavelengths: the same bits as `x.fract()`,
/// which is a libm call (`trunc`) on the baseline target, where this is a conversion to an
/// integer and back (exact below 2⁶³ wavelengths; beyond, x has no fraction left). Through
/// i64, one instruction each way, where u64 takes several on x86-64.
fn fraction_of_cycle(x: f64) -> f64 {
    debug_assert!(x >= 0.0);
    if x < 9.2e18 {
        x - (x as i64) as f64
    } else {
        0.0
    }
}

/// a modulo 2π in [0, 2π), the same bits as `a.rem_euclid(TAU)` for |a| < 4π, the range of a
/// difference of two angles in (−2π, π] (eq. 11), without its libm `fmod`: for TAU ≤ |a| <
/// 2·TAU, `a ∓ TAU` is exact (Sterbenz), as fmod's result is; outside that range, fmod itself.
/// Unlike `rem_euclid`, a remainder so small and negative that adding 2π rounds to 2π gives 0,
/// so the phase stays in [0, 2π).
fn wrap_angle(a: f64) -> f64 {
    let remainder = if a.abs() < TAU {
        a
    } else if a.abs() < 2.0 * TAU {
        a - TAU.copysign(a)
    } else {
        a % TAU
    };
    if remainder >= 0.0 {
        remainder
    } else if remainder + TAU < TAU {
        remainder + TAU
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The inline fraction and wrap give the bits of `fract` and `rem_euclid` they replace.
    #[test]
    fn inline_fraction_and_wrap_match_libm() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        for _ in 0..200_000 {
            let x: f64 = rng.random_range(0.0..1e7);
            assert_eq!(fraction_of_cycle(x).to_bits(), x.fract().to_bits(), "{x}");
            let a: f64 = rng.random_range(-2.0 * TAU..2.0 * TAU);
            assert_eq!(wrap_angle(a).to_bits(), a.rem_euclid(TAU).to_bits(), "{a}");
        }
        for a in [
            -TAU,
            -TAU / 2.0,
            0.0,
            TAU,
            2.0 * TAU - 1e-15,
            100.0,
            -100.0,
            1e300,
        ] {
            let w = wrap_angle(a);
            assert!((0.0..TAU).contains(&w) || w == a.rem_euclid(TAU), "{a}");
            if a != -TAU {
                assert_eq!(w.to_bits(), a.rem_euclid(TAU).to_bits(), "{a}");
            }
        }
        assert_eq!(wrap_angle(-1e-17), 0.0);
        assert_eq!(fraction_of_cycle(1e19), 0.0);
        assert_eq!(fraction_of_cycle(2.5), 0.5);
    }
    use crate::numerics::MeanEstimate;
    use rand::{RngExt, SeedableRng};

    fn small() -> Scenario {
        Scenario::builtin("small-test").unwrap()
    }

    #[test]
    fn path_loss_matches_the_3gpp_formulas() {
        // d = 10 m, f_c = 2 GHz: LoS 31.84 + 21.5 + 19·0.30103.
        let los = path_loss_db(10.0, 2.0, true);
        assert!((los - (31.84 + 21.5 + 19.0 * 2f64.log10())).abs() < 1e-12);
        let nlos = path_loss_db(10.0, 2.0, false);
        assert!((nlos - (32.4 + 23.0 + 20.0 * 2f64.log10())).abs() < 1e-12);
        // Below 1 m the distance is clamped; NLoS never beats LoS.
        assert_eq!(path_loss_db(0.1, 2.0, true), path_loss_db(1.0, 2.0, true));
        assert!(path_loss_db(1.0, 2.0, false) >= path_loss_db(1.0, 2.0, true));
    }

    #[test]
    fn no_irs_gain_is_the_direct_path_gain() {
        let s = small();
        let m = ChannelModel::new(&s);
        let mut w = vec![C64::new(0.0, 0.0); m.subsurfaces()];
        let q = [1.0, 1.0, 1.0];
        let d = m.evaluate(q, false, &mut w);
        let pl = path_loss_db((P3::from(q) - P3::from(s.ap().position)).norm(), 2.0, true);
        assert!(((d.h.norm_sqr() + d.tau) / 10f64.powf(-pl / 10.0) - 1.0).abs() < 1e-12);
        assert!(w.iter().all(|x| x.norm() == 0.0));
    }

    /// Lemma 1: λ(θ) equals the Monte Carlo mean of |c|² for random θ, with the direct link LoS
    /// and NLoS, in both groupings, with one IRS and with two. The sample mean must lie within 4 standard errors.
    #[test]
    fn expected_gain_matches_monte_carlo_mean() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let floors = [Grouping::Coherent, Grouping::Elements]
            .into_iter()
            .flat_map(|g| {
                [
                    Scenario::small_test_grouped(g),
                    Scenario::small_test_two_surfaces(g),
                ]
            });
        for s in floors {
            let grouping = s.surfaces()[0].grouping;
            let m = ChannelModel::new(&s);
            // (1, 1) sees the AP; the other two are behind the 1.5 m box.
            let points = [[1.0, 1.0, 1.0], [3.6, 2.0, 1.0], [4.0, 3.0, 0.5]];
            let mut saw_nlos = false;
            for q in points {
                saw_nlos |= m.is_blocked(s.ap().position, q);
                let theta: Vec<f64> = (0..m.subsurfaces())
                    .map(|_| rng.random::<f64>() * TAU)
                    .collect();
                let mut w = vec![C64::new(0.0, 0.0); m.subsurfaces()];
                let d = m.evaluate(q, true, &mut w);
                let closed = expected_gain(&d, &w, &theta);
                let draws = 200_000;
                let mut power_gain = MeanEstimate::default();
                m.sample_channels(&[q], Some(&theta), draws, &mut rng, |c| {
                    power_gain.add(c[0].norm_sqr());
                });
                let (mean, se) = (power_gain.mean(), power_gain.std_error());
                assert!(
                    (mean - closed).abs() < 4.0 * se,
                    "{grouping:?} at {q:?}: Monte Carlo {mean:e} ± {se:e} vs closed form {closed:e}"
                );
            }
            assert!(
                saw_nlos,
                "the test points must include a blocked direct link"
            );
        }
    }

    #[test]
    fn irs_does_not_serve_users_behind_it() {
        let s = small();
        let m = ChannelModel::new(&s);
        let irs = &m.surfaces[0];
        assert!(m.irs_user_link(irs, &P3::new(3.0, -0.5, 1.0)).is_none());
        assert!(m.irs_user_link(irs, &P3::new(3.0, 0.5, 1.0)).is_some());
    }
}
