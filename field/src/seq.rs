//! Readings in sequence order, each once: what a host does with the device's sequence
//! numbers (`docs/protocol.md`, "Reading") to survive a yanked cable without losing or
//! duplicating a reading. The `tangent` CLI's serial link and the browser app both keep
//! one [`SeqTracker`]; they differ only in how they wait and send.
//!
//! A reading whose number is not the next one is held back and reveals a gap; the host then
//! asks `History { after_seq: last() }`, feeds the replayed readings to [`SeqTracker::accept`]
//! and the closing `HistoryEnd { last_seq }` to [`SeqTracker::history_ended`], which gives
//! up the readings no longer on the device.

use std::collections::{BTreeMap, VecDeque};

use tangent_core::protocol::{codes, Reading};

/// Readings the device keeps for `History` ([`codes::HISTORY_LEN`]). Missing readings older
/// than this are given up at once; younger ones are asked for again.
pub const DEVICE_HISTORY: u32 = codes::HISTORY_LEN as u32;

/// Replays in a row that bring none of the missing readings before they are given up
/// anyway (a device with a shorter history than [`codes::HISTORY_LEN`]). On a noisy line a
/// replayed reading frame is damaged with probability p (≈ 0.45 at 1 % dropped + 1 %
/// corrupted bytes); giving up after k fruitless replays loses a reading the device still
/// has with probability pᵏ: 6 gave ≈ 1 % (seen under load), 12 gives < 10⁻⁴.
pub const MAX_FRUITLESS_REPLAYS: u32 = 12;

/// What a `HistoryEnd` meant.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum HistoryOutcome {
    /// The device's numbers went backwards: it restarted (call [`SeqTracker::restart`] and
    /// ask again).
    Rebooted,
    /// The replay is in; these ranges (inclusive) are no longer on the device and were given
    /// up.
    Done {
        /// Readings lost for good.
        lost: Vec<(u32, u32)>,
    },
}

/// Readings in sequence order, once each.
#[derive(Debug, Default, Clone)]
pub struct SeqTracker {
    /// Highest sequence number delivered (or skipped as lost).
    last: u32,
    /// Received ahead of a gap.
    pending: BTreeMap<u32, Reading>,
    /// In order, ready for the caller.
    ready: VecDeque<Reading>,
    /// Highest device timestamp seen (reboot detection).
    newest_ms: u64,
    /// The last replay left readings missing that the device should still have.
    recheck: bool,
    /// Replays in a row that brought none of the missing readings.
    fruitless_replays: u32,
}

impl SeqTracker {
    /// Takes a reading; returns whether it was a duplicate.
    pub fn accept(&mut self, r: Reading) -> bool {
        if r.seq <= self.last || self.pending.contains_key(&r.seq) {
            return true;
        }
        self.newest_ms = self.newest_ms.max(r.timestamp_ms);
        self.pending.insert(r.seq, r);
        self.drain();
        false
    }

    fn drain(&mut self) {
        while let Some(r) = self.pending.remove(&(self.last.wrapping_add(1))) {
            self.last = r.seq;
            self.ready.push_back(r);
        }
    }

    /// The next reading in order, if one is ready.
    pub fn pop_ready(&mut self) -> Option<Reading> {
        self.ready.pop_front()
    }

    /// Highest sequence number delivered (or given up on).
    pub fn last(&self) -> u32 {
        self.last
    }

    /// Delivers readings after `seq` from now on (forgetting what was held back).
    pub fn resume_after(&mut self, seq: u32) {
        self.restart();
        self.last = seq;
    }

    /// Highest device time seen (ms): a device reporting less has restarted.
    pub fn newest_ms(&self) -> u64 {
        self.newest_ms
    }

    /// Whether readings are missing: held back behind a gap, or left missing by the last
    /// replay.
    pub fn has_gap(&self) -> bool {
        !self.pending.is_empty() || self.recheck
    }

    /// Starts a `History` request: returns its `after_seq`.
    pub fn history_requested(&mut self) -> u32 {
        self.recheck = false;
        self.last
    }

    /// The `HistoryEnd { last_seq: device_last }` of the request that asked for readings
    /// after `after_seq`, once its replayed readings went through [`SeqTracker::accept`].
    pub fn history_ended(&mut self, after_seq: u32, device_last: u32) -> HistoryOutcome {
        if device_last < self.last {
            return HistoryOutcome::Rebooted;
        }
        // The device keeps its last DEVICE_HISTORY readings: older missing ones are gone.
        // Younger missing ones had their replay frame damaged: ask again, and give them up
        // only if replay after replay does not bring them (a device with a shorter history).
        let mut keep_from = device_last.saturating_sub(DEVICE_HISTORY - 1).max(1);
        if self.last == after_seq && self.missing_up_to(device_last) {
            self.fruitless_replays += 1;
            if self.fruitless_replays >= MAX_FRUITLESS_REPLAYS {
                keep_from = device_last.saturating_add(1);
            }
        } else {
            self.fruitless_replays = 0;
        }
        let lost = self.give_up_before(keep_from, device_last);
        if !lost.is_empty() {
            self.fruitless_replays = 0;
        }
        if self.missing_up_to(device_last) {
            self.recheck = true;
        }
        HistoryOutcome::Done { lost }
    }

    /// After a history replay that ended at `device_last`: the readings we still miss
    /// that are older than `keep_from` are no longer on the device and are given up
    /// (returned as ranges); younger ones stay missing (their replay frame was lost on the
    /// wire) for the next replay.
    pub fn give_up_before(&mut self, keep_from: u32, device_last: u32) -> Vec<(u32, u32)> {
        let mut lost = Vec::new();
        loop {
            self.drain();
            let next_have = self.pending.keys().next().copied();
            let missing_to = match next_have {
                Some(s) => s - 1,
                None if device_last > self.last => device_last,
                None => break,
            };
            let target = missing_to.min(keep_from.saturating_sub(1));
            if target <= self.last {
                break;
            }
            lost.push((self.last + 1, target));
            self.last = target;
        }
        lost
    }

    /// Whether readings up to `device_last` are still missing.
    pub fn missing_up_to(&self, device_last: u32) -> bool {
        self.has_gap() || device_last > self.last
    }

    /// Forgets everything (the device restarted: its numbers start again at 1).
    pub fn restart(&mut self) {
        self.last = 0;
        self.pending.clear();
        self.newest_ms = 0;
        self.recheck = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tangent_core::measurement::{Measurement, StemReading};
    use tangent_core::protocol::Method;
    use tangent_core::solvers::result::Flags;

    fn r(seq: u32) -> Reading {
        Reading {
            seq,
            timestamp_ms: seq as u64 * 10,
            calib_id: 1,
            exposure_us: 100,
            measurement: Measurement::Stem(StemReading {
                diameter: 0.3,
                uncertainty: 0.001,
                method: Method::CircleFit,
                distance: 1.0,
                tilt: None,
                axes: None,
                flags: Flags::default(),
                exposures: 1,
            }),
            stats: None,
            accelerometer: None,
        }
    }

    fn ready(t: &SeqTracker) -> Vec<u32> {
        t.ready.iter().map(|r| r.seq).collect()
    }

    #[test]
    fn tracker_orders_dedups_and_gives_up_on_lost() {
        let mut t = SeqTracker::default();
        assert!(!t.accept(r(1)));
        assert!(t.accept(r(1)));
        assert!(!t.accept(r(4)));
        assert!(t.has_gap());
        assert!(!t.accept(r(3)));
        assert!(t.accept(r(3)));
        assert_eq!(ready(&t), [1]);
        // History (keeping 3..) ended at 6 without 2, 5, 6: 2 is gone, 5 and 6 may come.
        assert_eq!(t.give_up_before(3, 6), vec![(2, 2)]);
        assert_eq!(t.last, 4);
        assert!(t.missing_up_to(6));
        // A device that kept nothing older than 7: 5 and 6 are gone too.
        assert_eq!(t.give_up_before(7, 6), vec![(5, 6)]);
        assert_eq!(ready(&t), [1, 3, 4]);
        assert_eq!(t.last, 6);
        assert!(!t.has_gap());
    }

    #[test]
    fn history_gives_up_what_fell_out_and_rechecks_what_did_not_come() {
        let mut t = SeqTracker::default();
        t.accept(r(1));
        // 100 readings made while away; the device keeps 37..=100.
        let after = t.history_requested();
        for s in 37..=100 {
            t.accept(r(s));
        }
        assert_eq!(
            t.history_ended(after, 100),
            HistoryOutcome::Done {
                lost: vec![(2, 36)]
            }
        );
        assert_eq!(t.last(), 100);
        assert!(!t.has_gap());
        // A replay that brings nothing of 101..=102 (frames lost): asked again, not given up.
        let after = t.history_requested();
        assert_eq!(
            t.history_ended(after, 102),
            HistoryOutcome::Done { lost: vec![] }
        );
        assert!(t.has_gap());
        // Numbers going backwards: a restart.
        assert_eq!(t.history_ended(t.last(), 5), HistoryOutcome::Rebooted);
    }

    #[test]
    fn fruitless_replays_give_up_in_the_end() {
        let mut t = SeqTracker::default();
        let mut lost = Vec::new();
        for _ in 0..MAX_FRUITLESS_REPLAYS {
            let after = t.history_requested();
            if let HistoryOutcome::Done { lost: l } = t.history_ended(after, 3) {
                lost.extend(l);
            }
        }
        assert_eq!(lost, vec![(1, 3)]);
        assert!(!t.has_gap());
    }
}
