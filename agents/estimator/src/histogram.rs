//! Percentiles in constant memory: an HdrHistogram of microseconds (three significant
//! digits), so a host that runs for days keeps its latency figures without keeping every value.
//! Every latency report of the rig (the estimator host, `rig up`, `rig bench`) goes through it.

/// Latencies [µs], three significant digits.
#[derive(Debug, Clone)]
pub struct Histogram(hdrhistogram::Histogram<u64>);

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

impl Histogram {
    pub fn new() -> Self {
        // Auto-resizing from 1 µs, three significant digits: cannot fail.
        Self(hdrhistogram::Histogram::new(3).unwrap_or_else(|_| unreachable!("3 digits is valid")))
    }

    /// Counts `v` [µs]; the histogram grows to hold it (a value beyond what it can ever
    /// hold counts as the largest it holds).
    pub fn record(&mut self, v: u64) {
        if self.0.record(v).is_err() {
            self.0.saturating_record(v);
        }
    }

    pub fn len(&self) -> u64 {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The value at quantile `q` (to three significant digits), 0 when empty.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.0.is_empty() {
            return 0;
        }
        self.0.value_at_quantile(q.clamp(0.0, 1.0))
    }

    /// Median, 99th percentile, largest, count.
    pub fn summary(&self) -> LatencySummary {
        LatencySummary {
            p50: self.quantile(0.5),
            p99: self.quantile(0.99),
            max: if self.0.is_empty() { 0 } else { self.0.max() },
            count: self.0.len(),
        }
    }
}

/// A latency's median, 99th percentile and largest value [µs] and how many were measured: the
/// one form every report (the estimator host, `rig up`, `rig bench`) gives them in. All 0 when
/// nothing was measured.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct LatencySummary {
    pub p50: u64,
    pub p99: u64,
    pub max: u64,
    pub count: u64,
}

impl LatencySummary {
    /// The summary of `values` [µs] (through the histogram: three significant digits).
    pub fn of(values: impl IntoIterator<Item = u64>) -> Self {
        let mut h = Histogram::new();
        values.into_iter().for_each(|v| h.record(v));
        h.summary()
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn quantiles_match_a_sorted_list_to_three_digits() {
        // Against the exact percentile of a sorted list, on a skewed sample.
        let values: Vec<u64> = (0..20_000u64).map(|k| (k * k) % 50_000 + k % 7).collect();
        let mut h = Histogram::new();
        values.iter().for_each(|&v| h.record(v));
        let mut sorted = values.clone();
        sorted.sort_unstable();
        for q in [0.0, 0.5, 0.9, 0.99, 1.0] {
            let exact = sorted[((sorted.len() - 1) as f64 * q).round() as usize];
            let got = h.quantile(q);
            // Three digits, and a rank either side (the sample's neighbours are ≤ 10 apart).
            assert!(
                got.abs_diff(exact) <= exact / 500 + 10,
                "q {q}: {got} vs {exact}"
            );
        }
        let sum = h.summary();
        assert!(sum.max.abs_diff(*sorted.last().unwrap()) <= sorted.last().unwrap() / 500);
        assert_eq!((sum.p50, sum.p99), (h.quantile(0.5), h.quantile(0.99)));
        assert_eq!(sum.count, 20_000);
        assert_eq!(LatencySummary::of(values.iter().copied()), sum);
        assert_eq!(LatencySummary::of([]), LatencySummary::default());
    }
}
