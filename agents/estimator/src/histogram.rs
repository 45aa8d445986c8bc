//! Percentiles in constant memory: a log-linear histogram of microseconds, exact below 1 ms
//! and within 1 % above (three significant digits), so a host that runs for days keeps its
//! latency figures without keeping every value.

/// Values below this are counted exactly.
const EXACT: u64 = 1000;
/// Buckets per decade above `EXACT` (three significant digits: 100..=999).
const PER_DECADE: usize = 900;

#[derive(Debug, Clone)]
pub struct Histogram {
    counts: Vec<u64>,
    n: u64,
    max: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

fn index(v: u64) -> usize {
    if v < EXACT {
        return v as usize;
    }
    let mut e = 0usize;
    let mut m = v;
    while m >= 1000 {
        m /= 10;
        e += 1;
    }
    EXACT as usize + (e - 1) * PER_DECADE + (m as usize - 100)
}

/// The smallest value of bucket `i`.
fn lower(i: usize) -> u64 {
    if i < EXACT as usize {
        return i as u64;
    }
    let k = i - EXACT as usize;
    let (e, m) = (k / PER_DECADE + 1, (k % PER_DECADE) as u64 + 100);
    m * 10u64.pow(e as u32)
}

impl Histogram {
    pub fn new() -> Self {
        Self {
            counts: vec![0; EXACT as usize + 18 * PER_DECADE],
            n: 0,
            max: 0,
        }
    }

    pub fn record(&mut self, v: u64) {
        if let Some(c) = self.counts.get_mut(index(v)) {
            *c += 1;
            self.n += 1;
            self.max = self.max.max(v);
        }
    }

    pub fn len(&self) -> u64 {
        self.n
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// The value at quantile `q` (the nearest rank, as a sorted list would give, to the
    /// bucket's lower bound), 0 when empty.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.n == 0 {
            return 0;
        }
        let rank = ((self.n - 1) as f64 * q.clamp(0.0, 1.0)).round() as u64;
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen > rank {
                return lower(i);
            }
        }
        self.max
    }

    /// Median, 99th percentile, largest, count.
    pub fn summary(&self) -> LatencySummary {
        LatencySummary {
            p50: self.quantile(0.5),
            p99: self.quantile(0.99),
            max: self.max,
            count: self.n,
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
    /// The summary of `values` [µs] (through the histogram: exact below 1 ms, within 1 % above).
    pub fn of(values: impl IntoIterator<Item = u64>) -> Self {
        let mut h = Histogram::new();
        values.into_iter().for_each(|v| h.record(v));
        h.summary()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buckets_round_trip_and_quantiles_match_a_sorted_list() {
        for v in [0, 1, 999, 1000, 1234, 99_999, 123_456_789] {
            let l = lower(index(v));
            assert!(l <= v && v - l <= v / 100, "{v} → bucket from {l}");
        }
        // Against the exact percentile of a sorted list, on a skewed sample.
        let values: Vec<u64> = (0..20_000u64).map(|k| (k * k) % 50_000 + k % 7).collect();
        let mut h = Histogram::new();
        values.iter().for_each(|&v| h.record(v));
        let mut sorted = values.clone();
        sorted.sort_unstable();
        for q in [0.0, 0.5, 0.9, 0.99, 1.0] {
            let exact = sorted[((sorted.len() - 1) as f64 * q).round() as usize];
            let got = h.quantile(q);
            assert!(
                got <= exact && exact - got <= exact / 100,
                "q {q}: {got} vs {exact}"
            );
        }
        let sum = h.summary();
        assert_eq!(sum.max, *sorted.last().unwrap());
        assert_eq!((sum.p50, sum.p99), (h.quantile(0.5), h.quantile(0.99)));
        assert_eq!(sum.count, 20_000);
        assert_eq!(LatencySummary::of(values.iter().copied()), sum);
        assert_eq!(LatencySummary::of([]), LatencySummary::default());
    }
}
