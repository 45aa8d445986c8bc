//! Whether the configured rate fits the board's read cycle — a pure verdict, said loudly at
//! start-up. Paper B's wiring cannot sample four joints at the examples' 1 kHz (its bus alone
//! needs 0.94 ms a cycle, and each round trip may wait for the USB adapter's latency timer:
//! docs/HARDWARE.md); a rig started too fast skips ticks and says so only in counters.

/// Cycles timed at start-up before the first tick.
pub const TIMED_CYCLES: usize = 20;

/// A read cycle takes longer than the tick: what was asked, what was timed, what fits.
#[derive(Debug, Clone, PartialEq)]
pub struct TooFast {
    pub rate_hz: f64,
    /// Median of the cycles timed at start-up [s].
    pub cycle_s: f64,
    /// The wire's own share of a cycle [s] (bytes at the baud rate; no delays).
    pub wire_s: f64,
    /// How many cycles were timed.
    pub timed: usize,
}

impl TooFast {
    /// The highest rate the timed cycle sustains [Hz].
    pub fn sustainable_hz(&self) -> f64 {
        1.0 / self.cycle_s
    }
}

impl std::fmt::Display for TooFast {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "WARNING: rate_hz = {} asks for a read cycle every {:.0} µs, but this board's cycle \
             takes {:.0} µs (median of {} timed; the wire alone {:.0} µs): \
             it samples at about {:.0} Hz and the other ticks are skipped. Set rate_hz to {:.0} or \
             less in the config (paper B's wiring: 250), or shorten the cycle — servos' Return \
             Delay Time 0, the USB adapter's latency timer 1 ms (docs/HARDWARE.md); \
             `rig bench bus` measures it",
            self.rate_hz,
            1e6 / self.rate_hz,
            self.cycle_s * 1e6,
            self.timed,
            self.wire_s * 1e6,
            self.sustainable_hz(),
            self.sustainable_hz().floor(),
        )
    }
}

/// `Some` when the median of the timed `cycles_s` [s] — or the wire alone — is longer than
/// the tick of `rate_hz`; `None` when a cycle fits (or nothing was timed and the wire fits).
pub fn verdict(rate_hz: f64, wire_s: f64, cycles_s: &[f64]) -> Option<TooFast> {
    let mut c: Vec<f64> = cycles_s.iter().copied().filter(|x| x.is_finite()).collect();
    c.sort_by(f64::total_cmp);
    let median = match c.len() {
        0 => 0.0,
        n if n % 2 == 1 => c[n / 2],
        n => 0.5 * (c[n / 2 - 1] + c[n / 2]),
    };
    let cycle_s = median.max(wire_s);
    (rate_hz > 0.0 && cycle_s * rate_hz > 1.0).then_some(TooFast {
        rate_hz,
        cycle_s,
        wire_s,
        timed: c.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_b_s_bus_at_1_khz_is_too_fast_and_the_warning_says_what_fits() {
        // docs/HARDWARE.md: 940 µs on the wire, + 5 replies × 500 µs Return Delay Time.
        let cycles = [3.44e-3, 3.40e-3, 3.50e-3, 3.44e-3, 3.45e-3];
        let v = verdict(1000.0, 0.94e-3, &cycles).unwrap();
        assert_eq!(v.cycle_s, 3.44e-3);
        assert!((v.sustainable_hz() - 290.7).abs() < 0.1);
        let text = v.to_string();
        for part in [
            "rate_hz = 1000",
            "every 1000 µs",
            "takes 3440 µs",
            "median of 5 timed",
            "wire alone 940 µs",
            "to 290 or less",
        ] {
            assert!(text.contains(part), "{part}: {text}");
        }
        // The same board at 250 Hz fits.
        assert_eq!(verdict(250.0, 0.94e-3, &cycles), None);
    }

    #[test]
    fn the_wire_alone_longer_than_the_tick_is_too_fast_even_untimed() {
        let v = verdict(2000.0, 0.94e-3, &[]).unwrap();
        assert_eq!(v.cycle_s, 0.94e-3);
        assert_eq!(verdict(1000.0, 0.94e-3, &[]), None);
        assert_eq!(verdict(1000.0, 0.94e-3, &[f64::NAN, 0.5e-3]), None);
    }
}
