//! Triggers waiting for their reading, shared by the triggered instruments (interferometer,
//! tracer): a trigger is latched as soon as the backend can read, or dropped with a warning
//! after the latch timeout (the sequencer then retries with a new trigger).

use crate::ros::Inbox;
use anyhow::Result;
use volcal_bag::pairing::trigger_type;
use volcal_msgs::msg::Trigger;

pub struct PendingTriggers {
    kind: u8,
    timeout_ns: i64,
    pending: Vec<(Trigger, i64)>,
}

impl PendingTriggers {
    /// For triggers of `kind` (`Trigger::KIND_BEAM` or `KIND_RANGE`).
    pub fn new(kind: u8, timeout_ns: i64) -> PendingTriggers {
        PendingTriggers { kind, timeout_ns, pending: Vec::new() }
    }

    /// Takes the new point and probe triggers of this kind (received at `now_ns`); returns the
    /// stamps of the on-the-fly segments of this kind that started.
    pub fn take_from(&mut self, sub: &mut Inbox<Trigger>, now_ns: i64) -> Vec<i64> {
        let mut starts = Vec::new();
        while let Some(t) = sub.next() {
            if t.kind != self.kind {
                continue;
            }
            if t.trigger_type == trigger_type::POINT || t.trigger_type == trigger_type::PROBE {
                self.pending.push((t, now_ns));
            } else if t.trigger_type == trigger_type::SEGMENT_START {
                starts.push(t.header.stamp.to_nanos());
            }
        }
        starts
    }

    /// Offers each pending trigger to `latch`, which returns whether it could read.
    pub fn service(&mut self, now_ns: i64, mut latch: impl FnMut(&Trigger) -> Result<bool>) -> Result<()> {
        let mut keep = Vec::new();
        for (t, received) in self.pending.drain(..) {
            if latch(&t)? {
                continue;
            }
            if now_ns - received > self.timeout_ns {
                log::warn!("trigger {}: no reading possible within the latch timeout; dropped", t.trigger_id);
            } else {
                keep.push((t, received));
            }
        }
        self.pending = keep;
        Ok(())
    }
}
