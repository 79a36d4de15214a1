//! Running mean and spread of the readings of a held trigger (Welford's algorithm).
//!
//! Welford's update keeps the mean `m` and the sum of squared deviations `S`:
//! `m_k = m_{k-1} + (x_k − m_{k-1}) / k`, `S_k = S_{k-1} + (x_k − m_{k-1})(x_k − m_k)`,
//! sample variance `S_k / (k − 1)`. Unlike `Σx² − (Σx)²/k` it does not cancel
//! catastrophically in `f32` when the spread (≈ 0.1 mm) is 10⁻³ of the value (≈ 0.3 m).
//! (Hand-written: five lines, and no `no_std` crate offers it without allocation.)

use tangent_core::protocol::RunningStats;

/// Running statistics of a series of diameters.
#[derive(Debug, Clone, Copy, Default)]
pub struct Welford {
    count: u32,
    mean: f64,
    m2: f64,
}

impl Welford {
    /// No readings yet.
    pub const fn new() -> Self {
        Welford {
            count: 0,
            mean: 0.0,
            m2: 0.0,
        }
    }

    /// Adds one value.
    pub fn push(&mut self, x: f64) {
        self.count = self.count.saturating_add(1);
        let delta = x - self.mean;
        self.mean += delta / self.count as f64;
        self.m2 += delta * (x - self.mean);
    }

    /// Number of values.
    pub fn count(&self) -> u32 {
        self.count
    }

    /// Count, mean and sample standard deviation (0 below two values).
    pub fn summary(&self) -> RunningStats {
        let spread = if self.count > 1 {
            libm::sqrt(self.m2 / (self.count - 1) as f64)
        } else {
            0.0
        };
        RunningStats {
            count: self.count,
            mean_m: self.mean as f32,
            spread_m: spread as f32,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_two_pass_formula() {
        let xs = [0.3141, 0.3139, 0.3144, 0.3140, 0.3142, 0.3138];
        let mut w = Welford::new();
        for x in xs {
            w.push(x);
        }
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0);
        let s = w.summary();
        assert_eq!(s.count, 6);
        // Results are rounded to f32 for the wire: relative error ≤ 2^-24 ≈ 6e-8.
        assert!(((s.mean_m as f64) - mean).abs() <= mean * 1.2e-7);
        assert!(((s.spread_m as f64) - var.sqrt()).abs() <= var.sqrt() * 1.2e-7);
    }

    #[test]
    fn one_value_has_zero_spread() {
        let mut w = Welford::new();
        w.push(0.5);
        assert_eq!(w.summary().spread_m, 0.0);
        assert_eq!(w.summary().mean_m, 0.5);
    }
}
