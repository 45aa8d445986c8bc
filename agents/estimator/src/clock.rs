//! Each board's clock, measured from its samples alone (no I/O: the host passes the times).
//!
//! A sample stamped `t_acq` by the board's clock arrives at `t_arr` by the host's:
//! `t_arr − t_acq = transit + (host clock − board clock)`. The transit is never negative and
//! is at its smallest for the quickest samples, so over a window the smallest `t_arr − t_acq`
//! is the clocks' difference plus the smallest transit (NTP's minimum filter, one way). The
//! estimate of the board's offset is its negation: positive when the board is ahead. One way,
//! a transit cannot be told from an offset: the estimate is low by the smallest transit of the
//! window (tens of µs on one machine, 0.1–0.5 ms across a switched lab network) — enough to say
//! that a board is off by a tick, not to synchronise it (chrony or PTP do that; docs/DEPLOY.md).
//!
//! What puts a sample into another tick than its peers' is a board's offset *against the other
//! boards*, so with several joints an offset is judged against the median of the others': a
//! board of 256 joints stamps each tick on the grid and sends it after reading them all, 0.5 ms
//! later — a transit that every joint of it shares, not a clock to synchronise. A rig of one
//! joint has no peers: its offset is judged as it is.
//!
//! Call contract: [`ClockWatch::on_sample`] with every accepted sample, in arrival order, with
//! the host's time at arrival. It returns an event when a window closes with news: the first
//! measurement of a joint, an offset (against its peers') going beyond half a tick, or coming
//! back within 0.4 tick. A joint whose peers have no measurement yet is judged at its next
//! window.

/// What a closed window says about a joint's clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockEvent {
    /// The joint's first measured offset [ns] (positive: the board is ahead of this host).
    Measured { joint: usize, offset_ns: i64 },
    /// The offset, against the peers' median, went beyond half a tick [ns] (the joint's own).
    Beyond { joint: usize, offset_ns: i64 },
    /// The offset came back within 0.4 tick [ns].
    Within { joint: usize, offset_ns: i64 },
}

#[derive(Debug, Clone, Copy, Default)]
struct Window {
    /// When it opened, host time [ns].
    start_ns: u64,
    /// The smallest arrival − stamp seen in it [ns].
    min_delay_ns: i64,
}

/// The clocks of every joint's board, seen from this host.
#[derive(Debug, Clone)]
pub struct ClockWatch {
    window_ns: u64,
    half_tick_ns: i64,
    open: Vec<Option<Window>>,
    offset_ns: Vec<Option<i64>>,
    beyond: Vec<bool>,
}

impl ClockWatch {
    /// For `joints` joints at a tick of `period_ns`, one estimate per `window_ns`.
    pub fn new(joints: usize, period_ns: u64, window_ns: u64) -> Self {
        Self {
            window_ns: window_ns.max(1),
            half_tick_ns: (period_ns / 2) as i64,
            open: vec![None; joints],
            offset_ns: vec![None; joints],
            beyond: vec![false; joints],
        }
    }

    /// Each joint's last estimate [ns] (positive: its board is ahead of this host).
    pub fn offsets_ns(&self) -> &[Option<i64>] {
        &self.offset_ns
    }

    /// What `joint`'s offset is judged against: the median of the other joints' last
    /// estimates; 0 for a rig of one joint; None while no other joint has one.
    fn peers_median(&self, joint: usize) -> Option<i64> {
        if self.offset_ns.len() == 1 {
            return Some(0);
        }
        let mut peers: Vec<i64> = self
            .offset_ns
            .iter()
            .enumerate()
            .filter(|&(k, _)| k != joint)
            .filter_map(|(_, o)| *o)
            .collect();
        if peers.is_empty() {
            return None;
        }
        peers.sort_unstable();
        let m = peers.len() / 2;
        Some(if peers.len() % 2 == 1 {
            peers[m]
        } else {
            peers[m - 1] / 2 + peers[m] / 2
        })
    }

    /// One accepted sample of `joint`, stamped `t_acq_ns`, arrived at `now_ns`.
    pub fn on_sample(&mut self, joint: usize, t_acq_ns: u64, now_ns: u64) -> Option<ClockEvent> {
        let delay = i128::from(now_ns) - i128::from(t_acq_ns);
        let delay = delay.clamp(i128::from(i64::MIN), i128::from(i64::MAX)) as i64;
        let w = self.open.get_mut(joint)?.get_or_insert(Window {
            start_ns: now_ns,
            min_delay_ns: delay,
        });
        w.min_delay_ns = w.min_delay_ns.min(delay);
        if now_ns.saturating_sub(w.start_ns) < self.window_ns {
            return None;
        }
        let offset_ns = w.min_delay_ns.saturating_neg();
        self.open[joint] = None;
        let first = self.offset_ns[joint].replace(offset_ns).is_none();
        let Some(reference) = self.peers_median(joint) else {
            return first.then_some(ClockEvent::Measured { joint, offset_ns });
        };
        let off = offset_ns.saturating_sub(reference).unsigned_abs();
        let event = if !self.beyond[joint] && off > self.half_tick_ns as u64 {
            self.beyond[joint] = true;
            Some(ClockEvent::Beyond { joint, offset_ns })
        } else if self.beyond[joint] && off * 5 < self.half_tick_ns as u64 * 4 {
            self.beyond[joint] = false;
            Some(ClockEvent::Within { joint, offset_ns })
        } else {
            None
        };
        match (first, event) {
            (true, None) => Some(ClockEvent::Measured { joint, offset_ns }),
            (_, e) => e,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    /// Samples at 1 kHz from a board `offset` ns ahead, with transits of 60 µs plus a
    /// deterministic 0–400 µs spread; the events of the first `n` samples.
    fn feed(w: &mut ClockWatch, from_ms: u64, n: u64, offset: i64) -> Vec<ClockEvent> {
        (0..n)
            .filter_map(|k| {
                let t_host = (from_ms + k) * MS;
                let transit = 60_000 + (k * 7919 % 400) * 1000;
                let arrival = t_host + transit;
                let stamp = (t_host as i64 + offset) as u64;
                w.on_sample(0, stamp, arrival)
            })
            .collect()
    }

    #[test]
    fn the_offset_is_the_smallest_arrival_delay_negated_low_by_the_smallest_transit() {
        let mut w = ClockWatch::new(1, MS, 1000 * MS);
        // 2 ms behind: stamps 2 ms early.
        let e = feed(&mut w, 10_000, 1001, -2 * MS as i64);
        // The smallest transit of the window is 60 µs: the estimate is −2.06 ms.
        assert_eq!(
            e,
            vec![ClockEvent::Beyond {
                joint: 0,
                offset_ns: -2_060_000
            }]
        );
        assert_eq!(w.offsets_ns(), &[Some(-2_060_000)]);
    }

    #[test]
    fn a_board_within_half_a_tick_is_measured_once_and_one_that_drifts_out_and_back_is_said_twice()
    {
        let mut w = ClockWatch::new(1, MS, 1000 * MS);
        // 0.2 ms ahead: measured, within half a tick (0.5 ms).
        let e = feed(&mut w, 0, 1001, 200_000);
        assert_eq!(
            e,
            vec![ClockEvent::Measured {
                joint: 0,
                offset_ns: 140_000
            }]
        );
        // Still there: nothing new.
        assert!(feed(&mut w, 1001, 1001, 200_000).is_empty());
        // 0.8 ms ahead: beyond; 0.45 ms: inside half a tick but not yet 0.4 tick — said once.
        let e = feed(&mut w, 2002, 1001, 800_000);
        assert_eq!(
            e,
            vec![ClockEvent::Beyond {
                joint: 0,
                offset_ns: 740_000
            }]
        );
        assert!(feed(&mut w, 3003, 1001, 510_000).is_empty());
        let e = feed(&mut w, 4004, 1001, 300_000);
        assert_eq!(
            e,
            vec![ClockEvent::Within {
                joint: 0,
                offset_ns: 240_000
            }]
        );
    }

    #[test]
    fn joints_that_share_a_transit_are_not_off_and_one_board_off_against_its_peers_is() {
        // Three joints of one big board: every sample arrives 0.6 ms after its stamp (the
        // board reads all its joints before it sends the tick): over half a tick one way, but
        // the same for all — nothing to say but the first measurements.
        let mut w = ClockWatch::new(3, MS, 1000 * MS);
        let mut events = Vec::new();
        for k in 0..2002u64 {
            let t = 10_000 * MS + k * MS;
            for j in 0..3 {
                events.extend(w.on_sample(j, t, t + 600_000));
            }
        }
        assert_eq!(events.len(), 3, "{events:?}");
        assert!(
            events.iter().all(|e| matches!(
                e,
                ClockEvent::Measured {
                    offset_ns: -600_000,
                    ..
                }
            )),
            "{events:?}"
        );
        // Joint 2's board goes 1 ms ahead of the others: beyond half a tick against them.
        let mut events = Vec::new();
        for k in 2002..3003u64 {
            let t = 10_000 * MS + k * MS;
            for j in 0..3 {
                let ahead = if j == 2 { MS } else { 0 };
                events.extend(w.on_sample(j, t + ahead, t + 600_000));
            }
        }
        assert_eq!(
            events,
            vec![ClockEvent::Beyond {
                joint: 2,
                offset_ns: 400_000
            }]
        );
    }

    #[test]
    fn a_joint_out_of_range_and_absurd_stamps_do_not_panic() {
        let mut w = ClockWatch::new(1, MS, MS);
        assert_eq!(w.on_sample(5, 0, 0), None);
        assert!(w.on_sample(0, u64::MAX, 0).is_none());
        let e = w.on_sample(0, u64::MAX, 2 * MS);
        assert!(matches!(e, Some(ClockEvent::Beyond { .. })), "{e:?}");
    }
}
