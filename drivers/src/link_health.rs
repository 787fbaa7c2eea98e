//! The health of a link (a Modbus bus, a serial line, a CAN interface):
//! how many requests it carried and how many times it failed, by kind,
//! counted by the task that owns the link and read by whoever reports
//! them (the daemon's metrics) while the link is in use.
//!
//! A [`LinkHealth`] is a cheap handle to shared counters: the owner
//! publishes into it, any clone reads a [`LinkCounts`] snapshot. Counts
//! only grow over the link's life. A transport counts what it can see:
//! a Modbus client every kind but decode errors and lost frames, a
//! streaming serial sensor refused frames and lost records, a CAN stream
//! lost frames.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Counts of one link's traffic and trouble, cumulative.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounts {
    /// Requests made (a Modbus call with its retries is one).
    pub requests: u64,
    /// Attempts that got no answer within their deadline.
    pub timeouts: u64,
    /// Answers that were a device's refusal (a Modbus exception).
    pub exceptions: u64,
    /// Attempts that failed on the link itself (I/O error, connection
    /// refused or closed, a garbled answer).
    pub link_errors: u64,
    /// Frames received that could not be decoded (bad checksum, bad
    /// framing) and were dropped.
    pub decode_errors: u64,
    /// Frames or records known to be lost (a sequence gap).
    pub lost: u64,
    /// Attempts repeated after a failed one.
    pub retries: u64,
    /// Connections opened again after a failure (the first is not counted).
    pub reconnects: u64,
}

impl LinkCounts {
    /// The error kinds and their counts, in a fixed order: `timeout`,
    /// `exception`, `link_error`, `decode_error`, `lost`, `retry`,
    /// `reconnect` (the `kind` label of the daemon's metric).
    pub fn by_kind(&self) -> [(&'static str, u64); 7] {
        [
            ("timeout", self.timeouts),
            ("exception", self.exceptions),
            ("link_error", self.link_errors),
            ("decode_error", self.decode_errors),
            ("lost", self.lost),
            ("retry", self.retries),
            ("reconnect", self.reconnects),
        ]
    }
}

#[derive(Debug, Default)]
struct Counters([AtomicU64; 8]);

impl Counters {
    fn store(&self, c: &LinkCounts) {
        let values = [
            c.requests,
            c.timeouts,
            c.exceptions,
            c.link_errors,
            c.decode_errors,
            c.lost,
            c.retries,
            c.reconnects,
        ];
        for (slot, v) in self.0.iter().zip(values) {
            slot.fetch_max(v, Ordering::Relaxed);
        }
    }

    fn load(&self) -> LinkCounts {
        let v: Vec<u64> = self.0.iter().map(|a| a.load(Ordering::Relaxed)).collect();
        LinkCounts {
            requests: v[0],
            timeouts: v[1],
            exceptions: v[2],
            link_errors: v[3],
            decode_errors: v[4],
            lost: v[5],
            retries: v[6],
            reconnects: v[7],
        }
    }
}

/// A link's name and its shared counters. See the module docs.
#[derive(Debug, Clone)]
pub struct LinkHealth {
    name: Arc<str>,
    counters: Arc<Counters>,
}

impl LinkHealth {
    /// Counters for the link named `name` (stable across tests: the
    /// link's address or role, not a session's port), all zero.
    pub fn new(name: &str) -> LinkHealth {
        LinkHealth {
            name: name.into(),
            counters: Arc::default(),
        }
    }

    /// The link's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Publish the owner's cumulative counts (a count never goes back).
    pub fn publish(&self, counts: &LinkCounts) {
        self.counters.store(counts);
    }

    /// The counts so far.
    pub fn counts(&self) -> LinkCounts {
        self.counters.load()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clones_read_what_the_owner_publishes_and_counts_never_go_back() {
        let owner = LinkHealth::new("tcp:10.0.0.5:502");
        let reader = owner.clone();
        owner.publish(&LinkCounts {
            requests: 10,
            timeouts: 2,
            ..LinkCounts::default()
        });
        owner.publish(&LinkCounts {
            requests: 9,
            exceptions: 1,
            ..LinkCounts::default()
        });
        let c = reader.counts();
        assert_eq!((c.requests, c.timeouts, c.exceptions), (10, 2, 1));
        assert_eq!(reader.name(), "tcp:10.0.0.5:502");
        assert_eq!(c.by_kind()[0], ("timeout", 2));
    }
}
