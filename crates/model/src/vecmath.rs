//! The natural logarithm and the exponential over whole rows of f64, for the gain map's inner
//! loop (docs/model.md §3): per cell the closed form needs two path gains (a logarithm and an
//! exponential each) and a logarithm for the dB value, and libm's scalar calls were a third of a
//! map's time. Written without branches or calls, the compiler vectorises these loops; they are
//! compiled for AVX-512, AVX2 + FMA and the baseline, the widest the processor has chosen at run
//! time (the `multiversion` crate).
//!
//! Accuracy, over the domains stated (tested against `f64::ln` and `f64::exp` on random
//! arguments): within 2 ulp of the correctly rounded result, while the maps they serve need
//! 10⁻⁹ dB, i.e. 2·10⁻¹⁰ relative. They are not general-purpose: no NaN, infinity or subnormal
//! handling, which the callers' arguments (path gains of distances clamped to ≥ 1 m, gains
//! above 10⁻³⁰⁰) never need.

use multiversion::multiversion;

/// ln 2 split so that k·LN2_HI is exact for |k| < 2¹¹ (its low 32 bits are zero) and
/// LN2_HI + LN2_LO = ln 2 to 2⁻¹⁰⁰ (Cody and Waite's reduction).
const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);

/// 1.5·2⁵²: adding it rounds a double of magnitude < 2⁵¹ to an integer (to nearest, ties to
/// even) that then sits in the low bits of the sum's mantissa; subtracting it again leaves the
/// rounded double. Inline, where `round` is a libm call on the baseline target.
pub const ROUNDING_SHIFT: f64 = 6_755_399_441_055_744.0;

/// The exponential's domain: within it 2^k of the reduction is a normal double.
pub const EXP_DOMAIN: f64 = 708.0;

/// 1/k! for k = 0..=13: Taylor's series of eᶻ on |r| ≤ ln2/2, where the first omitted term,
/// r¹⁴/14!, is below 4·10⁻¹⁸ (a thirtieth of an ulp).
const EXP_TAYLOR: [f64; 14] = [
    1.0,
    1.0,
    1.0 / 2.0,
    1.0 / 6.0,
    1.0 / 24.0,
    1.0 / 120.0,
    1.0 / 720.0,
    1.0 / 5_040.0,
    1.0 / 40_320.0,
    1.0 / 362_880.0,
    1.0 / 3_628_800.0,
    1.0 / 39_916_800.0,
    1.0 / 479_001_600.0,
    1.0 / 6_227_020_800.0,
];

/// 2/(2k+1) for k = 1..=11: ln m = 2 atanh s = 2s + s·R(s²) with s = (m−1)/(m+1) and
/// R(z) = Σ 2zᵏ/(2k+1); |s| ≤ 0.1716 for m ∈ [√½, √2], where the first omitted term is below
/// 10⁻¹⁹ relative.
const ATANH_TAIL: [f64; 11] = [
    2.0 / 3.0,
    2.0 / 5.0,
    2.0 / 7.0,
    2.0 / 9.0,
    2.0 / 11.0,
    2.0 / 13.0,
    2.0 / 15.0,
    2.0 / 17.0,
    2.0 / 19.0,
    2.0 / 21.0,
    2.0 / 23.0,
];

/// Σ c[k]·xᵏ for 14 coefficients by Estrin's scheme: neighbouring coefficients paired as
/// c[2i] + c[2i+1]·x, the pairs paired with x², and so on. Its longest chain of dependent
/// operations is 8, where Horner's is 26: a row's loop waits on that chain for each vector, and
/// the processor cannot overlap enough vectors to hide it.
#[inline(always)]
fn estrin14(x: f64, c: &[f64; 14]) -> f64 {
    let (x2, pair) = (x * x, |k: usize| c[k] + c[k + 1] * x);
    let (x4, quad) = (x2 * x2, |k: usize| pair(k) + pair(k + 2) * x2);
    let x8 = x4 * x4;
    let low = quad(0) + quad(4) * x4;
    let high = quad(8) + pair(12) * x4;
    low + high * x8
}

/// [`estrin14`] for 11 coefficients.
#[inline(always)]
fn estrin11(x: f64, c: &[f64; 11]) -> f64 {
    let (x2, pair) = (x * x, |k: usize| c[k] + c[k + 1] * x);
    let (x4, quad) = (x2 * x2, |k: usize| pair(k) + pair(k + 2) * x2);
    let x8 = x4 * x4;
    let low = quad(0) + quad(4) * x4;
    let high = pair(8) + c[10] * x2;
    low + high * x8
}

/// eˣ for |x| ≤ [`EXP_DOMAIN`] (arguments beyond it are clamped to it).
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    let x = x.clamp(-EXP_DOMAIN, EXP_DOMAIN);
    // x = k ln2 + r with k the integer nearest x/ln2, so |r| ≤ ln2/2.
    let shifted = x * std::f64::consts::LOG2_E + ROUNDING_SHIFT;
    let k = shifted - ROUNDING_SHIFT;
    let r = (x - k * LN2_HI) - k * LN2_LO;
    // 2^k: k + 1023 written into the exponent field; k sits in the low bits of `shifted`.
    let two_to_k = f64::from_bits((shifted.to_bits() << 52).wrapping_add(1023 << 52));
    estrin14(r, &EXP_TAYLOR) * two_to_k
}

/// ln x for positive normal x.
#[inline(always)]
pub fn ln(x: f64) -> f64 {
    let bits = x.to_bits();
    // x = 2^e · m with m ∈ [1, 2), then moved to [√½, √2) so that |s| below stays small.
    let mantissa = f64::from_bits((bits & 0x000F_FFFF_FFFF_FFFF) | 0x3FF0_0000_0000_0000);
    // The biased exponent as a double without an integer conversion: written into the low
    // bits of 2⁵²'s mantissa, then 2⁵² and the bias are taken off.
    let biased = f64::from_bits((bits >> 52) | 0x4330_0000_0000_0000);
    let mut e = biased - (4_503_599_627_370_496.0 + 1023.0);
    let high = mantissa > std::f64::consts::SQRT_2;
    let m = if high { mantissa * 0.5 } else { mantissa };
    e = if high { e + 1.0 } else { e };
    let f = m - 1.0; // exact (Sterbenz)
    let s = f / (2.0 + f);
    let z = s * s;
    // 2s = f − s·f, so ln m = f − s·(f − R): the exact f leads and the rounding falls on a
    // correction of about f²/2 (2s·(1 + …) directly was 3 ulp off near m = 1).
    let ln_m = f - s * (f - z * estrin11(z, &ATANH_TAIL));
    e * LN2_HI + (e * LN2_LO + ln_m)
}

/// `values[k] ← ln(values[k])`; every value positive and normal.
#[multiversion(targets("x86_64+avx512f+avx512dq+avx512vl", "x86_64+avx2+fma", "aarch64+neon"))]
pub fn ln_in_place(values: &mut [f64]) {
    for v in values {
        *v = ln(*v);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// |a − b| in units in the last place of b.
    fn ulps(a: f64, b: f64) -> f64 {
        let ulp = f64::from_bits(b.abs().to_bits() + 1) - b.abs();
        (a - b).abs() / ulp
    }

    #[test]
    fn exp_is_within_two_ulp_of_std() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(11);
        let mut worst = 0.0f64;
        let mut check = |x: f64| {
            let e = ulps(exp(x), x.exp());
            assert!(e <= 2.0, "exp({x:e}): {} vs {} ({e} ulp)", exp(x), x.exp());
            worst = worst.max(e);
        };
        for _ in 0..200_000 {
            check(rng.random_range(-EXP_DOMAIN..EXP_DOMAIN));
            // The gain map's range: 10^(−PL/20) for path losses of 10–300 dB.
            check(rng.random_range(-40.0..0.0));
        }
        for x in [
            0.0,
            -0.0,
            1e-300,
            -1e-17,
            0.5 * std::f64::consts::LN_2,
            -EXP_DOMAIN,
        ] {
            check(x);
        }
        assert!(
            worst > 0.0,
            "some argument is not exact: the comparison runs"
        );
    }

    #[test]
    fn ln_is_within_two_ulp_of_std() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(12);
        let check = |x: f64| {
            let (got, want) = (ln(x), x.ln());
            if want == 0.0 {
                assert_eq!(got, 0.0, "ln(1)");
            } else {
                let e = ulps(got, want);
                assert!(e <= 2.0, "ln({x:e}): {got} vs {want} ({e} ulp)");
            }
        };
        for _ in 0..200_000 {
            // Log-uniform over the normal doubles, and near 1 where ln is small.
            check(10f64.powf(rng.random_range(-307.0..308.0)));
            check(rng.random_range(0.5..2.0));
            check(rng.random_range(1.0..1e6));
        }
        for x in [
            1.0,
            std::f64::consts::SQRT_2,
            f64::from_bits(std::f64::consts::SQRT_2.to_bits() + 1),
            2.0,
            0.5,
            f64::MIN_POSITIVE,
            f64::MAX,
            1.0 + f64::EPSILON,
            1.0 - f64::EPSILON / 2.0,
        ] {
            check(x);
        }
    }

    /// The dispatched slice version computes what the scalar one does, lane by lane, on a
    /// length that leaves a remainder after any vector width.
    #[test]
    fn slice_version_matches_the_scalar_function() {
        let xs: Vec<f64> = (1..1003).map(|k| k as f64 * 0.37).collect();
        let mut logs = xs.clone();
        ln_in_place(&mut logs);
        for (x, l) in xs.iter().zip(&logs) {
            assert_eq!(l.to_bits(), ln(*x).to_bits());
        }
    }
}
