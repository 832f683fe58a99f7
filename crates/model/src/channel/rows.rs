//! Gain maps a row at a time (docs/model.md §2): the continuous closed form for a whole row of
//! cells, each link's path gain evaluated for the row in one vectorised pass
//! ([`crate::vecmath`]), with working arrays kept between rows so a row allocates nothing.

use super::{ChannelModel, LinkBudget, P3, path_loss_db_at};
use crate::geometry::{RowOfUsers, RowScratch, SightLines};

/// `out[k] = √L` = 10^(−PL/20) of links of squared length `d2[k]` (m², clamped to ≥ 1 m as
/// [`path_loss_db`] does, the InF-SH law of eqs. 41–42 in docs/model.md §2) and line of sight
/// `los[k]`, f = log₁₀ f_c: a whole row of a gain map
/// at once, vectorised (crate::vecmath). √L rather than L because the LoS amplitude is √L times
/// a constant and L = (√L)², so one exponential serves both.
#[multiversion::multiversion(targets(
    "x86_64+avx512f+avx512dq+avx512vl",
    "x86_64+avx2+fma",
    "aarch64+neon"
))]
fn root_path_gains(d2: &[f64], los: &[bool], f: f64, out: &mut [f64]) {
    let half_log10_e = 0.5 * std::f64::consts::LOG10_E;
    for ((root_gain, &d2), &los) in out.iter_mut().zip(d2).zip(los) {
        let log10_d = crate::vecmath::ln(d2.max(1.0)) * half_log10_e;
        let pl = path_loss_db_at(log10_d, f, los);
        *root_gain = crate::vecmath::exp(pl * (-std::f64::consts::LN_10 / 20.0));
    }
}

/// A row of a map's cells in the continuous closed form ([`ChannelModel::closed_form_row`]),
/// with the working arrays it needs: kept by a map's worker between rows, so a row allocates
/// nothing.
#[derive(Debug, Default)]
pub struct ClosedFormRow {
    /// |h̃| + ‖w̃‖₁ per cell.
    pub amplitude: Vec<f64>,
    /// τ per cell.
    pub tau: Vec<f64>,
    /// The cells whose link is evaluated: the free ones for the direct link, those in front of
    /// the surface for a surface's.
    served: Vec<bool>,
    /// The cells' y (x is the row's).
    ys: Vec<f64>,
    links: RowLinks,
}

/// One source's links to a row of users.
#[derive(Debug, Default)]
struct RowLinks {
    /// Squared lengths (m²).
    d2: Vec<f64>,
    los: Vec<bool>,
    /// √L, the square root of each link's path gain.
    root_gain: Vec<f64>,
    /// Scratch of the blockage test.
    scratch: RowScratch,
}

/// Which terms of the closed form a row sums ([`ChannelModel::closed_form_row`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RowTerms {
    /// The direct link and every surface: a gain map's cells.
    All,
    /// The direct link and every surface but surface `s`: what every candidate pose of a
    /// placement search shares (crate::placement).
    AllBut(usize),
    /// Surface `s` alone (‖w̃_s‖₁ and τ_s): one placement candidate's own part.
    Surface(usize),
}

impl RowTerms {
    /// True when surface `s`'s terms are summed.
    fn includes(self, s: usize) -> bool {
        match self {
            RowTerms::All => true,
            RowTerms::AllBut(moving) => s != moving,
            RowTerms::Surface(only) => s == only,
        }
    }
}

impl ClosedFormRow {
    fn resize(&mut self, cells: usize) {
        self.amplitude.resize(cells, 0.0);
        self.tau.resize(cells, 0.0);
        self.served.resize(cells, false);
        self.ys.resize(cells, 0.0);
        self.links.d2.resize(cells, 0.0);
        self.links.los.resize(cells, false);
        self.links.root_gain.resize(cells, 0.0);
    }
}

impl ChannelModel {
    /// True when [`Self::closed_form_row`] applies: every surface groups its elements
    /// `coherent`ly, so each surface's ‖w̃_s‖₁ is one link budget.
    pub fn closed_form_by_rows(&self) -> bool {
        self.surfaces.iter().all(|irs| irs.per_sub == 1)
    }

    /// [`Self::closed_form_terms`] for a whole row of a map at once: the users (x, y_min + j·Δ,
    /// height) for j < `skip.len()`, leaving cells where `skip[j]` holds (occupied) with
    /// unspecified values. Fills `row.amplitude[j]` = |h̃| + ‖w̃‖₁ and `row.tau[j]` = τ over the
    /// chosen `terms`, so that with [`RowTerms::All`] max_θ λ = amplitude² + τ (eq. 12). Only
    /// for models where [`Self::closed_form_by_rows`] holds. The links' path gains are
    /// evaluated for the whole row in one vectorised pass (crate::vecmath); the values equal
    /// the per-cell ones to rounding (a few ulp).
    #[allow(clippy::too_many_arguments)]
    pub fn closed_form_row(
        &self,
        terms: RowTerms,
        x: f64,
        y_min: f64,
        step: f64,
        height: f64,
        skip: &[bool],
        row: &mut ClosedFormRow,
    ) {
        debug_assert!(self.closed_form_by_rows());
        row.resize(skip.len());
        let ClosedFormRow {
            amplitude,
            tau,
            served,
            ys,
            links,
        } = row;
        for (j, y) in ys.iter_mut().enumerate() {
            *y = y_min + j as f64 * step; // as Grid::centre
        }
        let users = RowOfUsers { x, ys, z: height };
        // √(K/(K+1)): a LoS link's amplitude over √L (a NLoS link has K = 0: none).
        let los_share = (self.kappa / (self.kappa + 1.0)).sqrt();

        if matches!(terms, RowTerms::Surface(_)) {
            amplitude.iter_mut().for_each(|a| *a = 0.0);
            tau.iter_mut().for_each(|t| *t = 0.0);
        } else {
            for (served, &skipped) in served.iter_mut().zip(skip) {
                *served = !skipped;
            }
            self.links_from(&self.ap_sight, users, served, links);
            let direct_scattered = [1.0, 1.0 / (self.kappa + 1.0)]; // L/(K+1) over L, NLoS and LoS
            for (j, (a, t)) in amplitude.iter_mut().zip(tau.iter_mut()).enumerate() {
                let (root_gain, los) = (links.root_gain[j], links.los[j]);
                *a = if los { root_gain * los_share } else { 0.0 };
                *t = root_gain * root_gain * direct_scattered[usize::from(los)];
            }
        }

        let surfaces = self
            .surfaces
            .iter()
            .enumerate()
            .filter(|&(s, irs)| irs.faces_ap && terms.includes(s))
            .map(|(_, irs)| irs);
        for irs in surfaces {
            // A user on or behind the surface's plane is not served: no link to evaluate.
            for (j, served) in served.iter_mut().enumerate() {
                let user = P3::new(x, users.ys[j], height);
                *served = !skip[j] && (user - irs.centre).dot(&irs.normal) > 0.0;
            }
            self.links_from(&irs.sight, users, served, links);
            // ‖w̃_s‖₁ over √L_IM for a LoS user link (eq. 12, all N_s sub-surfaces alike), and
            // Lemma 1's scattered power over L_IM for a NLoS and a LoS user link.
            let reflected =
                irs.subsurfaces as f64 * irs.weight * irs.ap_link.los_amplitude() * los_share;
            let per_unit_gain = |los: bool| LinkBudget {
                los,
                path_gain: 1.0,
                rician_k: if los { self.kappa } else { 0.0 },
            };
            let scattered =
                [false, true].map(|los| Self::surface_scattered_power(irs, &per_unit_gain(los)));
            for j in (0..served.len()).filter(|&j| served[j]) {
                let (root_gain, los) = (links.root_gain[j], links.los[j]);
                if los {
                    amplitude[j] += reflected * root_gain;
                }
                tau[j] += root_gain * root_gain * scattered[usize::from(los)];
            }
        }
    }

    /// The links from `sight`'s source to the users of a row: squared lengths, line of sight
    /// (blockage tested where `wanted[j]` holds, a row at a time; elsewhere NLoS, untested)
    /// and √L of each.
    fn links_from(
        &self,
        sight: &SightLines,
        users: RowOfUsers,
        wanted: &[bool],
        links: &mut RowLinks,
    ) {
        let source = sight.source();
        for (d2, &y) in links.d2.iter_mut().zip(users.ys) {
            *d2 = (P3::new(users.x, y, users.z) - source).norm_squared();
        }
        let RowLinks {
            los,
            scratch,
            d2,
            root_gain,
        } = links;
        let horizon = sight.horizon(&self.obstructions);
        self.obstructions
            .blocks_row(source, horizon, users, wanted, scratch, los);
        for (los, &wanted) in los.iter_mut().zip(wanted) {
            *los = wanted && !*los;
        }
        root_path_gains(d2, los, self.carrier_log10, root_gain);
    }
}
