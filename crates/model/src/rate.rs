//! Expected rates of the MRU sharing the AP with K static robots (paper Section III,
//! docs/model.md §4), and the closed-form power split that maximises the MRU's rate for given
//! expected gains.
//!
//! Users are indexed 0 = MRU, 1..=K = SRUs in scenario order. Rates are the Jensen upper bounds
//! of the paper (eqs. 22 and 24), written with the expected gains λ_l:
//!
//! * NOMA, decoding order π (π[0] decoded first): the user at position t sees the users decoded
//!   after it as interference, R_t = log2(1 + p_t / (Σ_{u>t} p_u + σ²/λ_t)) (eq. 22); SIC
//!   requires the channel ordering λ_{π[0]} ≤ λ_{π[1]} ≤ … (eq. 26h, generalised).
//! * OMA, K+1 equal bands: R_l = log2(1 + (K+1) λ_l p_l / σ²) / (K+1) (eq. 24, generalised).
//!
//! **Closed-form power split (NOMA).** Write S_t = Σ_{u≥t} p_u for the power of the users from
//! position t on (S_0 ≤ P_max, S_{K+1} = 0) and a_t = 2^{r̄_t} − 1. User t's rate constraint is
//! affine in the tail powers:  S_t ≥ 2^{r̄_t} S_{t+1} + a_t σ²/λ_t.  With the MRU at position k,
//! its rate log2((S_k + σ²/λ_m)/(S_{k+1} + σ²/λ_m)) increases with S_k and decreases with
//! S_{k+1}, and the two are constrained by disjoint sets of users. Hence:
//! 1. the users after the MRU (stronger SRUs) get exactly their targets: run the recursion with
//!    equality from S_{K+1} = 0 down to the smallest feasible S_{k+1};
//! 2. the users before it (weaker SRUs) get exactly their targets out of the full budget: run it
//!    backwards from S_0 = P_max, S_{t+1} = (S_t − a_t σ²/λ_t)/2^{r̄_t}, up to the largest S_k;
//! 3. the MRU takes p_m = S_k − S_{k+1}, feasible iff this is ≥ 0.
//!
//! Unrolling the recursion gives the equivalent feasibility test for an MRU rate r:
//! Σ_t c_t/λ_t ≤ P_max with c_t = σ² a_t Π_{u<t} 2^{r̄_u} (MRU's target r̄ = r), a sum of convex
//! terms in λ, so every superlevel set of the MRU rate is convex: the rate is quasi-concave and
//! increasing in the gains. The certificate relies on this.
//!
//! **OMA** decouples: SRU k needs p_k = (2^{(K+1) r̄_k} − 1) σ² / ((K+1) λ_k), the MRU takes the rest.

use crate::scenario::Scenario;
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// How the MRU and the SRUs share the AP.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Access {
    /// Power-domain NOMA with successive interference cancellation.
    Noma,
    /// K+1 equal orthogonal frequency bands.
    Oma,
}

impl FromStr for Access {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        crate::input::parse_name(s)
    }
}

impl fmt::Display for Access {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Access::Noma => "noma",
            Access::Oma => "oma",
        })
    }
}

/// P (W) from P (dBm).
pub fn dbm_to_watts(dbm: f64) -> f64 {
    10f64.powf((dbm - 30.0) / 10.0)
}

/// The users' fixed data for one map: power budget, noise and the SRUs' targets.
#[derive(Debug, Clone)]
pub struct RateModel {
    /// NOMA or OMA: which rate formula (eq. 22 or 24) and which decoding orders apply.
    pub access: Access,
    /// P_max (W).
    pub p_max_w: f64,
    /// σ² (W).
    pub noise_w: f64,
    /// r̄ per user; entry 0 (the MRU) is unused.
    targets: Vec<f64>,
    /// 2^{r̄_l} per user (NOMA's tail growth), precomputed: the solvers evaluate the split
    /// millions of times per map, each of which took two `exp2` per SRU before.
    growth: Vec<f64>,
    /// The SINR each user's target needs: 2^{r̄_l} − 1 (NOMA), 2^{(K+1) r̄_l} − 1 (OMA, K+1 bands).
    excess: Vec<f64>,
    /// Candidate decoding orders (NOMA: all (K+1)! permutations; OMA: the identity only).
    orders: Vec<Vec<u8>>,
}

/// The best configuration of the AP for given gains.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PowerSplit {
    /// The MRU's rate (bit/s/Hz).
    pub mru_rate: f64,
    /// Power per user (W), MRU first.
    pub power_w: Vec<f64>,
    /// Index into [`RateModel::orders`] (NOMA) or 0 (OMA).
    pub order: u8,
}

impl RateModel {
    /// The scenario's users: P_max and σ² from the AP, r̄_s from each SRU. The antenna gains
    /// and the fade margin of the link budget (docs/model.md §3.1) enter as an effective noise
    /// σ² − G_tx − G_rx + M (dB), shared by every user as σ² is, so that P_max and the power
    /// split stay transmit powers; all three are 0 unless the scenario states them.
    pub fn for_scenario(scenario: &Scenario, access: Access) -> RateModel {
        let targets: Vec<f64> = scenario.srus.iter().map(|s| s.min_rate_bps_hz).collect();
        let ap = scenario.ap();
        let channel = &scenario.channel;
        let budget = ap.antenna_gain_dbi + channel.rx_antenna_gain_dbi - channel.fade_margin_db;
        RateModel::new(
            access,
            dbm_to_watts(ap.tx_power_dbm),
            dbm_to_watts(ap.noise_dbm - budget),
            &targets,
        )
    }

    /// The users' data from P_max and σ² (W) and the SRUs' minimum rates r̄_s (bit/s/Hz), in
    /// scenario order.
    pub fn new(access: Access, p_max_w: f64, noise_w: f64, sru_targets: &[f64]) -> RateModel {
        let users = sru_targets.len() + 1;
        let mut targets = vec![0.0];
        targets.extend_from_slice(sru_targets);
        let orders = match access {
            Access::Noma => permutations(users),
            Access::Oma => vec![(0..users as u8).collect()],
        };
        let growth = targets.iter().map(|r| r.exp2()).collect();
        let excess = targets
            .iter()
            .map(|r| match access {
                Access::Noma => r.exp2() - 1.0,
                Access::Oma => (users as f64 * r).exp2() - 1.0,
            })
            .collect();
        RateModel {
            access,
            p_max_w,
            noise_w,
            targets,
            growth,
            excess,
            orders,
        }
    }

    /// r̄_l, user l's minimum rate (entry 0, the MRU's, is 0 and unused).
    pub fn targets(&self) -> &[f64] {
        &self.targets
    }

    /// K + 1.
    pub fn users(&self) -> usize {
        self.targets.len()
    }

    /// The decoding orders searched; order `k` lists user indices, decoded first first.
    pub fn orders(&self) -> &[Vec<u8>] {
        &self.orders
    }

    /// The MRU's best rate over the power split (and, for NOMA, the decoding orders whose channel
    /// ordering the gains satisfy), or `None` if some SRU cannot meet its rate.
    /// `lambdas[l]` is user l's expected gain λ_l (linear).
    pub fn best(&self, lambdas: &[f64]) -> Option<PowerSplit> {
        self.best_order(lambdas)
            .map(|(_, k)| self.split(lambdas, k).expect("feasible order"))
    }

    /// The admissible decoding order with the MRU's best [`Self::mru_score`] at these gains,
    /// and that score; `None` if no admissible order serves every SRU.
    ///
    /// SIC admits only orders along increasing gains, so with distinct gains exactly one of
    /// the (K+1)! orders is admissible: it is found by sorting the users (O(K²)) and is the
    /// only one scored. Equal gains admit several orders, and then every order is tried, so
    /// the answer is always the best over all of them (tested against that search).
    #[inline]
    pub fn best_order(&self, lambdas: &[f64]) -> Option<(f64, usize)> {
        if let Some(k) = self.only_admissible(lambdas) {
            return self
                .mru_score_ignoring_ordering(lambdas, k)
                .map(|score| (score, k));
        }
        let mut best: Option<(f64, usize)> = None;
        for k in 0..self.orders.len() {
            if let Some(score) = self.mru_score(lambdas, k)
                && best.is_none_or(|(b, _)| score > b)
            {
                best = Some((score, k));
            }
        }
        best
    }

    /// The one order SIC admits at these gains: OMA's only order, or under NOMA the users by
    /// strictly increasing gain, as an index into [`Self::orders`] (which lists the
    /// permutations in lexicographic order, so the index is the permutation's Lehmer rank).
    /// `None` when two gains are equal (or NaN), or for more users than it sorts on the stack.
    #[inline]
    fn only_admissible(&self, lambdas: &[f64]) -> Option<usize> {
        const MOST: usize = 8;
        let n = lambdas.len();
        if self.access == Access::Oma {
            return Some(0);
        }
        if n > MOST {
            return None;
        }
        // Insertion sort of the user indices by gain.
        let mut users = [0u8; MOST];
        for u in 0..n {
            let mut at = u;
            while at > 0 && lambdas[users[at - 1] as usize] > lambdas[u] {
                users[at] = users[at - 1];
                at -= 1;
            }
            users[at] = u as u8;
        }
        // Strictly increasing, which also refuses NaN.
        if !users[..n]
            .windows(2)
            .all(|w| lambdas[w[0] as usize] < lambdas[w[1] as usize])
        {
            return None;
        }
        // Lehmer rank: at each position, the unused users below the one placed there, times
        // the orders of the positions after it.
        let mut rank = 0;
        let mut used = 0u32;
        for (t, &u) in users[..n].iter().enumerate() {
            let below = (used & ((1u32 << u) - 1)).count_ones() as usize;
            rank = rank * (n - t) + (u as usize - below);
            used |= 1 << u;
        }
        Some(rank)
    }

    /// The MRU's best rate for one decoding order (NOMA) or for OMA, without allocating.
    /// `None` if the gains violate the order's channel ordering or an SRU cannot be served.
    #[inline]
    pub fn mru_rate(&self, lambdas: &[f64], order: usize) -> Option<f64> {
        self.mru_score(lambdas, order)
            .map(|score| self.rate_of_score(score))
    }

    /// A number that orders like the MRU's rate for one order, without its logarithm: 1 + SINR
    /// (NOMA, eq. 22: (S_k + σ²/λ_m)/(S_{k+1} + σ²/λ_m); OMA, eq. 24: 1 + (K+1) λ_m p_m/σ²). Searches compare
    /// scores and take one logarithm at the end ([`Self::rate_of_score`]).
    #[inline]
    pub fn mru_score(&self, lambdas: &[f64], order: usize) -> Option<f64> {
        if self.access == Access::Noma
            && self.orders[order]
                .windows(2)
                .any(|w| lambdas[w[0] as usize] > lambdas[w[1] as usize])
        {
            return None;
        }
        self.mru_score_ignoring_ordering(lambdas, order)
    }

    /// [`Self::mru_score`] without the SIC channel-ordering check. It increases in every λ_l
    /// (the tail powers shrink and the head powers grow as gains rise), which is what lets the
    /// certificate bound it at an upper corner of the gains.
    #[inline]
    pub fn mru_score_ignoring_ordering(&self, lambdas: &[f64], order: usize) -> Option<f64> {
        let (p_m, interference) = self.allocate(lambdas, order, |_, _| {})?;
        Some(match self.access {
            Access::Oma => 1.0 + self.users() as f64 * lambdas[0] * p_m / self.noise_w,
            Access::Noma => {
                let floor = interference + self.noise_w / lambdas[0];
                (floor + p_m) / floor
            }
        })
    }

    /// The MRU's rate (bit/s/Hz) of a score: log2(score), divided by the K+1 bands for OMA.
    #[inline]
    pub fn rate_of_score(&self, score: f64) -> f64 {
        if score == f64::NEG_INFINITY {
            return score; // no split serves every SRU
        }
        match self.access {
            Access::Oma => score.log2() / self.users() as f64,
            Access::Noma => score.log2(),
        }
    }

    /// The power per user achieving [`Self::mru_rate`] for an order.
    pub fn split(&self, lambdas: &[f64], order: usize) -> Option<PowerSplit> {
        let mru_rate = self.mru_rate(lambdas, order)?;
        let mut power = vec![0.0; self.users()];
        let (p_m, _) = self.allocate(lambdas, order, |u, p| power[u] = p)?;
        power[0] = p_m;
        Some(PowerSplit {
            mru_rate,
            power_w: power,
            order: order as u8,
        })
    }

    /// The closed-form split of the module doc: every SRU at exactly its target, the MRU with
    /// the rest. Returns the MRU's power p_m and the power of the users decoded after it
    /// (S_{k+1}, its NOMA interference; 0 for OMA), or `None` if p_m would be negative. Each SRU's
    /// power goes to `set(user, watts)`; the solvers' hot loop passes a no-op, which compiles away.
    fn allocate(
        &self,
        lambdas: &[f64],
        order: usize,
        mut set: impl FnMut(usize, f64),
    ) -> Option<(f64, f64)> {
        let noise = self.noise_w;
        match self.access {
            Access::Oma => {
                let bands = self.users() as f64;
                let mut left = self.p_max_w;
                for (l, &lam) in lambdas.iter().enumerate().skip(1) {
                    let p = self.excess[l] * noise / (bands * lam);
                    set(l, p);
                    left -= p;
                }
                (left >= 0.0).then_some((left, 0.0))
            }
            Access::Noma => {
                let pi = &self.orders[order];
                let k = pi
                    .iter()
                    .position(|&u| u == 0)
                    .expect("the MRU is in every order");
                // S_t for t > k, from the strongest user down: S_t = 2^{r̄_t} S_{t+1} + a_t σ²/λ_t.
                let mut tail = 0.0;
                for &u in pi[k + 1..].iter().rev() {
                    let u = u as usize;
                    let next = self.growth[u] * tail + self.excess[u] * noise / lambdas[u];
                    set(u, next - tail);
                    tail = next;
                }
                // S_t for t ≤ k, from the full budget up: S_{t+1} = (S_t − a_t σ²/λ_t)/2^{r̄_t}.
                let mut head = self.p_max_w;
                for &u in &pi[..k] {
                    let u = u as usize;
                    let next = (head - self.excess[u] * noise / lambdas[u]) / self.growth[u];
                    set(u, head - next);
                    head = next;
                }
                (head >= tail).then_some((head - tail, tail))
            }
        }
    }

    /// Every user's rate for given channel power gains, powers and order. With the expected
    /// gains λ_l these are the Jensen bounds (eqs. 22/24); with instantaneous gains |c_l|² they are
    /// the exact rates (eqs. 21/23) whose mean the bounds over-estimate.
    pub fn rates(&self, gains: &[f64], power_w: &[f64], order: usize) -> Vec<f64> {
        let users = self.users();
        let noise = self.noise_w;
        match self.access {
            Access::Oma => {
                let bands = users as f64;
                (0..users)
                    .map(|l| (1.0 + bands * gains[l] * power_w[l] / noise).log2() / bands)
                    .collect()
            }
            Access::Noma => {
                let pi = &self.orders[order];
                let mut rates = vec![0.0; users];
                let mut later = 0.0;
                for &u in pi.iter().rev() {
                    let u = u as usize;
                    rates[u] = (1.0 + gains[u] * power_w[u] / (gains[u] * later + noise)).log2();
                    later += power_w[u];
                }
                rates
            }
        }
    }

    /// Total power needed for the MRU to reach `r` with every SRU at its target, for one order:
    /// Σ_t c_t/λ_t (see the module doc); feasible iff ≤ P_max.
    pub fn required_power(&self, lambdas: &[f64], order: usize, r: f64) -> f64 {
        let score = match self.access {
            Access::Oma => (self.users() as f64 * r).exp2(),
            Access::Noma => r.exp2(),
        };
        let mut costs = vec![0.0; self.users()];
        self.power_costs(order, score, &mut costs);
        costs.iter().zip(lambdas).map(|(c, l)| c / l).sum()
    }

    /// The coefficients of the feasibility test Σ_l c_l/λ_l ≤ P_max (module doc) for the MRU at
    /// `score` ([`Self::mru_score`]: 2^r for NOMA, 2^{(K+1)r} for OMA), by user index. Each is
    /// affine and non-decreasing in the score: the MRU's own is (score − 1)·κ, and under NOMA
    /// the users decoded after it carry the factor 2^r = score.
    pub fn power_costs(&self, order: usize, score: f64, out: &mut [f64]) {
        let noise = self.noise_w;
        match self.access {
            Access::Oma => {
                let bands = self.users() as f64;
                for (l, c) in out.iter_mut().enumerate() {
                    let excess = if l == 0 { score - 1.0 } else { self.excess[l] };
                    *c = excess * noise / bands;
                }
            }
            Access::Noma => {
                let mut scale = 1.0;
                for &u in &self.orders[order] {
                    let u = u as usize;
                    let (excess, growth) = if u == 0 {
                        (score - 1.0, score)
                    } else {
                        (self.excess[u], self.growth[u])
                    };
                    out[u] = scale * excess * noise;
                    scale *= growth;
                }
            }
        }
    }

    /// The supremum of the MRU's score under `order` (channel ordering ignored) over the
    /// half-space {λ > 0 : g·λ ≤ budget}, g ≥ 0; `None` if not even score 1 (rate 0) fits.
    ///
    /// Exact, by Cauchy–Schwarz: min{Σ c_l/λ_l : g·λ ≤ B} = (Σ_l √(c_l g_l))²/B, so score x is
    /// reachable iff (Σ_l √(c_l(x) g_l))² ≤ P_max·B, which is monotone in x and solved by
    /// bisection on the rate (the returned end is the infeasible one, so the value is never
    /// below the supremum). +∞ when g gives no weight to a user whose cost grows with x.
    pub fn score_bound(&self, order: usize, g: &[f64], budget: f64) -> Option<f64> {
        const MOST: usize = 8;
        const STEPS: usize = 64;
        let users = self.users();
        let mut costs = [0.0; MOST];
        let mut fits = |score: f64| {
            self.power_costs(order, score, &mut costs[..users]);
            let a: f64 = costs[..users]
                .iter()
                .zip(g)
                .map(|(c, g)| (c * g).max(0.0).sqrt())
                .sum();
            a * a <= self.p_max_w * budget
        };
        if users > MOST || budget.is_nan() || budget <= 0.0 {
            return Some(f64::INFINITY); // no claim
        }
        if !fits(1.0) {
            return None;
        }
        // Bracket the score by doubling the rate, then bisect it.
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        while fits(hi.exp2()) {
            (lo, hi) = (hi, 2.0 * hi);
            if hi > 4096.0 {
                return Some(f64::INFINITY);
            }
        }
        for _ in 0..STEPS {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if fits(mid.exp2()) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(hi.exp2())
    }

    /// Human-readable labels of an order's users: "mru", "sru0", …
    pub fn order_labels(&self, order: usize) -> Vec<String> {
        self.orders[order]
            .iter()
            .map(|&u| user_label(u as usize))
            .collect()
    }
}

/// "mru" for user 0, "sru{k}" for SRU k (0-based, scenario order).
pub fn user_label(user: usize) -> String {
    if user == 0 {
        "mru".to_string()
    } else {
        format!("sru{}", user - 1)
    }
}

fn permutations(n: usize) -> Vec<Vec<u8>> {
    fn extend(prefix: &mut Vec<u8>, n: usize, out: &mut Vec<Vec<u8>>) {
        if prefix.len() == n {
            out.push(prefix.clone());
            return;
        }
        for u in 0..n as u8 {
            if !prefix.contains(&u) {
                prefix.push(u);
                extend(prefix, n, out);
                prefix.pop();
            }
        }
    }
    let mut out = Vec::new();
    extend(&mut Vec::new(), n, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Brute force over the power split (K = 1): the SRU's share of P_max on logarithmic grids
    /// towards 0 and towards P_max (10⁻¹⁴ … 1 either way): the closed form must match it.
    fn brute_force_k1(model: &RateModel, lambdas: &[f64]) -> Option<f64> {
        let mut best: Option<f64> = None;
        let steps = 20_000;
        let shares = (0..=steps).flat_map(|s| {
            let t = 10f64.powf(-14.0 * (1.0 - s as f64 / steps as f64));
            [t, 1.0 - t]
        });
        let shares: Vec<f64> = shares.collect();
        for k in 0..model.orders().len() {
            for &share in &shares {
                let ps = model.p_max_w * share;
                let power = [model.p_max_w - ps, ps];
                let pi = &model.orders()[k];
                if model.access == Access::Noma && lambdas[pi[0] as usize] > lambdas[pi[1] as usize]
                {
                    continue;
                }
                let rates = model.rates(lambdas, &power, k);
                if rates[1] >= model.targets()[1] - 1e-12 && best.is_none_or(|b| rates[0] > b) {
                    best = Some(rates[0]);
                }
            }
        }
        best
    }

    proptest! {
        #[test]
        fn closed_form_split_matches_brute_force(
            lm in -90.0f64..-50.0, ls in -90.0f64..-50.0, target in 0.2f64..4.0, noma in any::<bool>()
        ) {
            let access = if noma { Access::Noma } else { Access::Oma };
            let model = RateModel::new(access, 0.1, 1e-12, &[target]);
            let lambdas = [10f64.powf(lm / 10.0), 10f64.powf(ls / 10.0)];
            let best = model.best(&lambdas);
            let brute = brute_force_k1(&model, &lambdas);
            match (best, brute) {
                (Some(b), Some(r)) => {
                    // The grid can only do worse than the optimum, by at most one grid step.
                    prop_assert!(b.mru_rate >= r - 1e-9, "closed form {} < brute force {}", b.mru_rate, r);
                    prop_assert!(b.mru_rate - r < 0.01, "closed form {} ≫ brute force {}", b.mru_rate, r);
                    let rates = model.rates(&lambdas, &b.power_w, b.order as usize);
                    prop_assert!((rates[0] - b.mru_rate).abs() < 1e-9);
                    prop_assert!(rates[1] >= target - 1e-9);
                    prop_assert!(b.power_w.iter().sum::<f64>() <= model.p_max_w * (1.0 + 1e-12));
                }
                (None, None) => {}
                (b, r) => prop_assert!(false, "closed form {:?} vs brute force {:?}", b, r),
            }
        }

        /// K = 2: the split meets every SRU exactly, sums to P_max, and the unrolled feasibility
        /// test Σ c_t/λ_t ≤ P_max agrees with the rate.
        #[test]
        fn k2_split_is_consistent(
            l in proptest::collection::vec(-85.0f64..-55.0, 3), t1 in 0.1f64..2.0, t2 in 0.1f64..2.0, noma in any::<bool>()
        ) {
            let access = if noma { Access::Noma } else { Access::Oma };
            let model = RateModel::new(access, 0.1, 1e-12, &[t1, t2]);
            let lambdas: Vec<f64> = l.iter().map(|d| 10f64.powf(d / 10.0)).collect();
            for k in 0..model.orders().len() {
                if let Some(split) = model.split(&lambdas, k) {
                    let rates = model.rates(&lambdas, &split.power_w, k);
                    prop_assert!((rates[0] - split.mru_rate).abs() < 1e-9);
                    prop_assert!((rates[1] - t1).abs() < 1e-9 && (rates[2] - t2).abs() < 1e-9);
                    prop_assert!((split.power_w.iter().sum::<f64>() - 0.1).abs() < 1e-12);
                    let need = model.required_power(&lambdas, k, split.mru_rate);
                    prop_assert!((need / 0.1 - 1.0).abs() < 1e-9, "required power {need}");
                }
            }
        }
    }

    proptest! {
        /// The order [`RateModel::best_order`] picks by sorting is the best over every order,
        /// for 1–4 SRUs, NOMA and OMA, gains drawn from a few values so that ties (several
        /// admissible orders) are common.
        #[test]
        fn the_sorted_order_is_the_best_of_all(
            srus in 1usize..=4,
            noma in any::<bool>(),
            targets in prop::collection::vec(0.05f64..2.0, 4),
            gains in prop::collection::vec(0usize..6, 5),
            p_max_dbm in 10.0f64..30.0,
        ) {
            let access = if noma { Access::Noma } else { Access::Oma };
            let model = RateModel::new(access, dbm_to_watts(p_max_dbm), 1e-12, &targets[..srus]);
            let levels = [1e-9, 3e-9, 1e-8, 2.5e-8, 1e-7, 4e-7];
            let lambdas: Vec<f64> = gains[..=srus].iter().map(|&g| levels[g]).collect();
            let scan = (0..model.orders().len())
                .filter_map(|k| model.mru_score(&lambdas, k).map(|s| (s, k)))
                .fold(None, |best: Option<(f64, usize)>, (s, k)| {
                    if best.is_none_or(|(b, _)| s > b) { Some((s, k)) } else { best }
                });
            prop_assert_eq!(model.best_order(&lambdas), scan, "{:?}", lambdas);
        }
    }

    proptest! {
        /// [`RateModel::score_bound`] is the supremum of an order's score over the half-space
        /// g·λ ≤ B: no point of the half-space's boundary (where the score, increasing in every
        /// gain, is largest) scores above it, and its Cauchy–Schwarz minimiser λ_l ∝ √(c_l/g_l)
        /// attains it.
        #[test]
        fn the_half_space_bound_is_the_supremum(
            srus in 1usize..=4,
            noma in any::<bool>(),
            targets in prop::collection::vec(0.05f64..2.0, 4),
            g in prop::collection::vec(0.01f64..1.0, 5),
            budget_db in -75.0f64..-50.0,
            directions in prop::collection::vec(prop::collection::vec(0.01f64..1.0, 5), 64),
            order_pick in 0usize..120,
        ) {
            let access = if noma { Access::Noma } else { Access::Oma };
            let model = RateModel::new(access, 0.1, 1e-12, &targets[..srus]);
            let n = srus + 1;
            let order = order_pick % model.orders().len();
            let (g, budget) = (&g[..n], 10f64.powf(budget_db / 10.0));
            let bound = model.score_bound(order, g, budget);
            for u in &directions {
                let along: f64 = u[..n].iter().zip(g).map(|(u, g)| u * g).sum();
                let lambdas: Vec<f64> = u[..n].iter().map(|u| u * budget / along).collect();
                let score = model.mru_score_ignoring_ordering(&lambdas, order);
                match (score, bound) {
                    (Some(s), Some(b)) => prop_assert!(s <= b * (1.0 + 1e-12), "{s} > {b}"),
                    (Some(s), None) => prop_assert!(false, "{s} reached, bound says none"),
                    (None, _) => {}
                }
            }
            if let Some(b) = bound.filter(|b| b.is_finite()) {
                let mut costs = vec![0.0; n];
                model.power_costs(order, b, &mut costs);
                let roots: f64 = costs.iter().zip(g).map(|(c, g)| (c * g).sqrt()).sum();
                let minimiser: Vec<f64> =
                    costs.iter().zip(g).map(|(c, g)| budget * (c / g).sqrt() / roots).collect();
                let s = model.mru_score_ignoring_ordering(&minimiser, order).unwrap_or(1.0);
                prop_assert!(s >= b * (1.0 - 1e-9), "the minimiser scores {s} < {b}");
                prop_assert!(s <= b * (1.0 + 1e-9), "the minimiser scores {s} > {b}");
            }
        }
    }

    #[test]
    fn orders_cover_all_permutations() {
        let m = RateModel::new(Access::Noma, 1.0, 1.0, &[1.0, 1.0, 1.0]);
        assert_eq!(m.orders().len(), 24);
        assert_eq!(
            RateModel::new(Access::Oma, 1.0, 1.0, &[1.0, 1.0])
                .orders()
                .len(),
            1
        );
        assert_eq!(m.order_labels(0), vec!["mru", "sru0", "sru1", "sru2"]);
    }

    #[test]
    fn access_names_round_trip() {
        for access in [Access::Noma, Access::Oma] {
            assert_eq!(access.to_string().parse::<Access>(), Ok(access));
        }
        assert!("tdma".parse::<Access>().unwrap_err().contains("noma"));
    }
}
