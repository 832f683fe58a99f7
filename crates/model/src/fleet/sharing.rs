//! Robots served by one AP sharing its power (docs/model.md §6.5): NOMA with successive
//! interference cancellation, or OMA in equal bands, each robot's requirement a rate.
//!
//! Powers are written as fractions f of the AP's budget P_max, and ρ = P_max·G/σ² is the SNR a
//! robot of unit gain would get with all of it (G the link budget's antenna gains and margin,
//! §3.1), so robot l of gain λ_l has the SNR λ_l ρ f_l alone.
//!
//! * NOMA (eq. 22 generalised): SIC decodes the weaker robots first, so the only admissible
//!   order is by gain (eq. 26h generalised; ties by request order). Each robot at exactly its
//!   rate needs, from the strongest down, S_t = 2^{r_t} S_{t+1} + (2^{r_t} − 1)/(λ_t ρ) for the
//!   tail S_t = Σ_{u≥t} f_u ([`crate::rate`]'s recursion); the group is served iff S_0 ≤ 1.
//!   No other split serves it with less power, so no order or split search is needed.
//! * OMA (eq. 24 generalised, n robots, n equal bands): f_l = (2^{n r_l} − 1)/(n λ_l ρ); served
//!   iff Σ f_l ≤ 1.
//!
//! The rest of the budget, 1 − Σ f, is left unused: every robot gets exactly its rate.

use crate::rate::Access;

/// How one AP serves its robots at one instant.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Share {
    /// Per robot (the group's order), its power as a fraction of P_max.
    pub fractions: Vec<f64>,
    /// NOMA: the group's indices in decoding order (decoded first first); OMA: empty.
    pub order: Vec<usize>,
}

/// The least power meeting every rate `rates[l]` (bit/s/Hz) of robots of gains `gains[l]`
/// (linear) at an AP of budget SNR `rho`; `None` when it exceeds the AP's budget.
pub(crate) fn share(access: Access, rho: f64, gains: &[f64], rates: &[f64]) -> Option<Share> {
    let n = gains.len();
    match access {
        Access::Oma => {
            let bands = n as f64;
            let fractions: Vec<f64> = gains
                .iter()
                .zip(rates)
                .map(|(&g, &r)| exp2_m1(bands * r) / (bands * g * rho))
                .collect();
            (fractions.iter().sum::<f64>() <= 1.0).then_some(Share {
                fractions,
                order: Vec::new(),
            })
        }
        Access::Noma => {
            let mut order: Vec<usize> = (0..n).collect();
            order.sort_by(|&a, &b| gains[a].total_cmp(&gains[b]).then(a.cmp(&b)));
            let mut fractions = vec![0.0; n];
            let mut tail = 0.0;
            for &u in order.iter().rev() {
                let next = rates[u].exp2() * tail + exp2_m1(rates[u]) / (gains[u] * rho);
                fractions[u] = next - tail;
                tail = next;
            }
            (tail <= 1.0).then_some(Share { fractions, order })
        }
    }
}

/// 2^x − 1 without losing digits for small x.
fn exp2_m1(x: f64) -> f64 {
    (x * std::f64::consts::LN_2).exp_m1()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rate::RateModel;

    /// Against the rate model's own split over every decoding order: the group is served
    /// exactly when some order's required power fits, and then with the least of them; every
    /// robot gets exactly its rate by the rate formulas (eqs. 22 and 24).
    #[test]
    fn the_split_is_the_least_power_of_any_order() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let (p_max, noise) = (0.1, 1e-12);
        let rho = p_max / noise;
        let mut served = 0;
        for case in 0..400 {
            let n = 1 + case % 4;
            // λρ from 0.1 to 1000 (−10 to 30 dB of SNR with all the power).
            let gains: Vec<f64> = (0..n)
                .map(|_| 10f64.powf(-12.0 - 4.0 * next() + 3.0))
                .collect();
            let rates: Vec<f64> = (0..n).map(|_| 0.1 + 2.5 * next()).collect();
            for access in [Access::Noma, Access::Oma] {
                // User 0 of the rate model is the first robot, at its own rate.
                let model = RateModel::new(access, p_max, noise, &rates[1..]);
                let least = (0..model.orders().len())
                    .filter(|&k| {
                        access == Access::Oma
                            || model.orders()[k]
                                .windows(2)
                                .all(|w| gains[w[0] as usize] <= gains[w[1] as usize])
                    })
                    .map(|k| model.required_power(&gains, k, rates[0]))
                    .fold(f64::INFINITY, f64::min);
                match share(access, rho, &gains, &rates) {
                    Some(s) => {
                        served += 1;
                        let total: f64 = s.fractions.iter().sum();
                        assert!(
                            (total * p_max / least - 1.0).abs() < 1e-9,
                            "{total} {least}"
                        );
                        let powers: Vec<f64> = s.fractions.iter().map(|f| f * p_max).collect();
                        let order = match access {
                            Access::Oma => 0,
                            Access::Noma => model
                                .orders()
                                .iter()
                                .position(|o| {
                                    o.iter().map(|&u| u as usize).eq(s.order.iter().copied())
                                })
                                .unwrap(),
                        };
                        for (got, want) in model.rates(&gains, &powers, order).iter().zip(&rates) {
                            assert!((got - want).abs() < 1e-9, "{got} {want}");
                        }
                    }
                    None => assert!(least > p_max * (1.0 - 1e-12), "{least} fits"),
                }
            }
        }
        assert!(served > 150 && served < 650, "{served} of 800 served");
    }
}
