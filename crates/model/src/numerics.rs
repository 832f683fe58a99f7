//! Small numerical tools used by several models, written once: the ℓ₁ norm of a complex
//! vector, golden-section search, and a streaming mean with its standard error.

use nalgebra::Complex;

/// ‖a‖₁ = Σ|a_n|: the coherent gain of a vector whose phases can all be aligned (the IRS term
/// of the closed form, docs/model.md eq. 12).
#[inline]
pub fn l1_norm(a: &[Complex<f64>]) -> f64 {
    a.iter().map(|x| x.norm()).sum()
}

/// The maximum of a unimodal `f` on [lo, hi] by golden-section search: `iterations` steps
/// shrink the bracket to (hi − lo)·0.618^iterations. Returns (x, f(x)) at the better of the two
/// final interior points (the first on a tie); the endpoints are the caller's to compare.
pub fn golden_section_max(
    mut f: impl FnMut(f64) -> f64,
    lo: f64,
    hi: f64,
    iterations: usize,
) -> (f64, f64) {
    // 1/φ = (√5 − 1)/2, the ratio by which the bracket shrinks per step.
    let ratio = 0.5 * (5f64.sqrt() - 1.0);
    let (mut lo, mut hi) = (lo, hi);
    let mut x1 = hi - ratio * (hi - lo);
    let mut x2 = lo + ratio * (hi - lo);
    let (mut f1, mut f2) = (f(x1), f(x2));
    for _ in 0..iterations {
        if f1 >= f2 {
            hi = x2;
            x2 = x1;
            f2 = f1;
            x1 = hi - ratio * (hi - lo);
            f1 = f(x1);
        } else {
            lo = x1;
            x1 = x2;
            f1 = f2;
            x2 = lo + ratio * (hi - lo);
            f2 = f(x2);
        }
    }
    if f1 >= f2 { (x1, f1) } else { (x2, f2) }
}

/// A running mean of samples and the standard error of that mean (Monte Carlo checks).
#[derive(Debug, Clone, Copy, Default)]
pub struct MeanEstimate {
    count: usize,
    sum: f64,
    sum_of_squares: f64,
}

impl MeanEstimate {
    /// Adds one sample.
    #[inline]
    pub fn add(&mut self, sample: f64) {
        self.count += 1;
        self.sum += sample;
        self.sum_of_squares += sample * sample;
    }

    /// The mean of the samples so far (NaN before the first).
    pub fn mean(&self) -> f64 {
        self.sum / self.count as f64
    }

    /// √(Var/n) with the population variance (n is large in every use); 0 when rounding makes
    /// the variance estimate negative.
    pub fn std_error(&self) -> f64 {
        let n = self.count as f64;
        let mean = self.mean();
        ((self.sum_of_squares / n - mean * mean).max(0.0) / n).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_section_finds_a_parabola_peak() {
        let (x, fx) = golden_section_max(|x| -(x - 0.3) * (x - 0.3), 0.0, 1.0, 60);
        assert!((x - 0.3).abs() < 1e-7 && fx <= 0.0 && fx > -1e-14);
    }

    #[test]
    fn mean_and_standard_error() {
        let mut m = MeanEstimate::default();
        for x in [1.0, 2.0, 3.0, 4.0] {
            m.add(x);
        }
        assert_eq!(m.mean(), 2.5);
        assert!((m.std_error() - (1.25f64 / 4.0).sqrt()).abs() < 1e-15);
    }
}
