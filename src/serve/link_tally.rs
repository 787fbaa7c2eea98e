//! What the metrics have taken of a running test's link counts.
//!
//! A rig's links are opened afresh for every test, so their counts start
//! at zero each time, while a Prometheus counter must only grow over the
//! daemon's life. The metrics therefore add what a link's counts have
//! grown since they last looked: at every scrape while the test runs, and
//! once more when it ends. Whoever looks first takes the growth; nothing
//! is counted twice.

use std::sync::Mutex;

use motorbench_drivers::{LinkCounts, LinkHealth};

/// A test's links and the counts already taken of each.
#[derive(Debug, Default)]
pub struct LinkTally {
    links: Vec<LinkHealth>,
    taken: Mutex<Vec<LinkCounts>>,
}

/// How far a link's counts grew since the last look.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LinkGrowth {
    /// The link's name (its configured address or role).
    pub link: String,
    /// Growth of each count.
    pub grown: LinkCounts,
}

impl LinkTally {
    /// A tally of `links`, nothing taken yet.
    pub fn new(links: Vec<LinkHealth>) -> LinkTally {
        let taken = Mutex::new(vec![LinkCounts::default(); links.len()]);
        LinkTally { links, taken }
    }

    /// How far each link's counts grew since the last call (all of them
    /// at the first), and take it.
    pub fn take_growth(&self) -> Vec<LinkGrowth> {
        let mut taken = self.taken.lock().unwrap_or_else(|p| p.into_inner());
        self.links
            .iter()
            .zip(taken.iter_mut())
            .map(|(link, before)| {
                let now = link.counts();
                let grown = growth(before, &now);
                *before = now;
                LinkGrowth {
                    link: link.name().to_string(),
                    grown,
                }
            })
            .collect()
    }
}

fn growth(before: &LinkCounts, now: &LinkCounts) -> LinkCounts {
    let d = |a: u64, b: u64| b.saturating_sub(a);
    LinkCounts {
        requests: d(before.requests, now.requests),
        timeouts: d(before.timeouts, now.timeouts),
        exceptions: d(before.exceptions, now.exceptions),
        link_errors: d(before.link_errors, now.link_errors),
        decode_errors: d(before.decode_errors, now.decode_errors),
        lost: d(before.lost, now.lost),
        retries: d(before.retries, now.retries),
        reconnects: d(before.reconnects, now.reconnects),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn growth_is_taken_once() {
        let bus = LinkHealth::new("tcp:10.0.0.5:502");
        let tally = LinkTally::new(vec![bus.clone()]);
        bus.publish(&LinkCounts {
            requests: 100,
            timeouts: 2,
            ..LinkCounts::default()
        });
        let g = tally.take_growth();
        assert_eq!(g[0].link, "tcp:10.0.0.5:502");
        assert_eq!((g[0].grown.requests, g[0].grown.timeouts), (100, 2));
        bus.publish(&LinkCounts {
            requests: 150,
            timeouts: 2,
            exceptions: 3,
            ..LinkCounts::default()
        });
        let g = tally.take_growth();
        assert_eq!(
            (
                g[0].grown.requests,
                g[0].grown.timeouts,
                g[0].grown.exceptions
            ),
            (50, 0, 3)
        );
        assert_eq!(tally.take_growth()[0].grown, LinkCounts::default());
    }
}
