//! The per-scan time histogram of a run: quantiles in memory that does not grow with the
//! number of scans.

/// Log-spaced histogram of per-scan times: quantiles within [`TimeHistogram::RELATIVE_ERROR`]
/// in memory that does not grow with the number of scans.
#[derive(Debug, Clone)]
pub struct TimeHistogram {
    counts: Vec<u64>,
    total: u64,
}

impl Default for TimeHistogram {
    fn default() -> Self {
        Self {
            counts: vec![0; Self::bins()],
            total: 0,
        }
    }
}

impl TimeHistogram {
    /// Smallest time binned apart (ms); anything below lands in the first bin.
    const MIN_MS: f64 = 1e-4;
    /// Largest time binned apart (ms); anything above lands in the last bin.
    const MAX_MS: f64 = 1e7;
    /// Ratio of a bin's upper to its lower edge.
    const RATIO: f64 = 1.01;
    /// Largest relative error of a quantile inside the binned range (half a bin).
    pub const RELATIVE_ERROR: f64 = 0.005;

    fn bins() -> usize {
        ((Self::MAX_MS / Self::MIN_MS).ln() / Self::RATIO.ln()).ceil() as usize + 1
    }

    /// Adds one time (ms); NaN and negative values are ignored.
    pub fn add(&mut self, ms: f64) {
        if ms.is_nan() || ms < 0.0 {
            return;
        }
        let last = self.counts.len() - 1;
        let bin = ((ms.max(Self::MIN_MS) / Self::MIN_MS).ln() / Self::RATIO.ln()).floor();
        self.counts[(bin.max(0.0) as usize).min(last)] += 1;
        self.total += 1;
    }

    /// The `q`-quantile by nearest rank, as [`quantile`](crate::matching::quantile) takes it, at the bin's geometric
    /// centre; NaN for no times.
    #[must_use]
    pub fn quantile(&self, q: f64) -> f64 {
        if self.total == 0 {
            return f64::NAN;
        }
        let rank = ((q * self.total as f64).ceil() as u64).clamp(1, self.total);
        let mut seen = 0;
        for (i, &c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return Self::MIN_MS * Self::RATIO.powf(i as f64 + 0.5);
            }
        }
        f64::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::matching::quantile;
    use rand::{Rng, SeedableRng};

    /// The histogram is the bounded twin of the exact nearest-rank quantile: within half a bin.
    #[test]
    fn time_histogram_quantiles_are_within_half_a_bin_of_exact() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        for _ in 0..20 {
            let n = rng.random_range(1..5000);
            let times: Vec<f64> = (0..n)
                .map(|_| 10f64.powf(rng.random_range(-2.0..3.0)))
                .collect();
            let mut h = TimeHistogram::default();
            times.iter().for_each(|&t| h.add(t));
            for q in [0.0, 0.25, 0.5, 0.9, 0.99, 1.0] {
                let (exact, binned) = (quantile(&times, q), h.quantile(q));
                assert!(
                    (binned / exact - 1.0).abs() <= TimeHistogram::RELATIVE_ERROR + 1e-9,
                    "q {q}: {binned} vs {exact}"
                );
            }
        }
        assert!(TimeHistogram::default().quantile(0.5).is_nan());
    }
}
