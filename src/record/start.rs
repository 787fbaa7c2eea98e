//! The wall-clock start of a test, to the nanosecond.
//!
//! Contract version 2 puts every message at its wall-clock time
//! (`log_time` = Unix time in ns), so that Foxglove and other MCAP tools
//! place a record on the day it was taken and two records of one day line
//! up. The start is carried twice in the `motorbench.test` metadata:
//! `started_at` (RFC 3339 with nanoseconds) and `start_time_ns` (the same
//! instant as an integer); `log_time − start_time_ns` is the time since the
//! start, which is what the bench, identification and the report use.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The instant a test started, Unix time in ns.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct TestStart {
    unix_ns: u64,
}

impl TestStart {
    /// Now, by the system clock.
    pub fn now() -> TestStart {
        TestStart::from_system_time(SystemTime::now())
    }

    /// The instant `t`; one before 1970 is taken as the epoch.
    pub fn from_system_time(t: SystemTime) -> TestStart {
        let since = t.duration_since(UNIX_EPOCH).unwrap_or_default();
        TestStart {
            unix_ns: u64::try_from(since.as_nanos()).unwrap_or(u64::MAX),
        }
    }

    /// The instant `unix_ns` ns after the Unix epoch.
    pub fn from_unix_ns(unix_ns: u64) -> TestStart {
        TestStart { unix_ns }
    }

    /// Parses an RFC 3339 UTC time (`Z` or `+00:00`, any number of
    /// fractional digits); `None` for anything else.
    pub fn parse_rfc3339(text: &str) -> Option<TestStart> {
        humantime::parse_rfc3339(text)
            .ok()
            .map(TestStart::from_system_time)
    }

    /// Nanoseconds since the Unix epoch.
    pub fn unix_ns(self) -> u64 {
        self.unix_ns
    }

    /// RFC 3339 with nanoseconds, e.g. `2026-12-03T15:48:50.123456789Z`:
    /// the metadata's `started_at`.
    pub fn rfc3339(self) -> String {
        humantime::format_rfc3339_nanos(self.system_time()).to_string()
    }

    /// RFC 3339 to the second, e.g. `2026-12-03T15:48:50Z`: for file
    /// names and for people.
    pub fn rfc3339_seconds(self) -> String {
        humantime::format_rfc3339_seconds(self.system_time()).to_string()
    }

    fn system_time(self) -> SystemTime {
        UNIX_EPOCH + Duration::from_nanos(self.unix_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rfc3339_round_trips_to_the_nanosecond() {
        let t = TestStart::from_unix_ns(1_796_312_930_123_456_789);
        assert_eq!(t.rfc3339(), "2026-12-03T15:48:50.123456789Z");
        assert_eq!(t.rfc3339_seconds(), "2026-12-03T15:48:50Z");
        assert_eq!(TestStart::parse_rfc3339(&t.rfc3339()), Some(t));
        assert_eq!(
            TestStart::parse_rfc3339("2026-12-03T15:48:50Z").map(TestStart::unix_ns),
            Some(1_796_312_930_000_000_000)
        );
    }

    #[test]
    fn other_text_is_not_a_start() {
        for bad in ["", "yesterday", "2026-12-03", "2026-12-03T15:48:50+01:00"] {
            assert_eq!(TestStart::parse_rfc3339(bad), None, "{bad}");
        }
    }

    #[test]
    fn now_is_after_the_epoch_and_round_trips() {
        let t = TestStart::now();
        assert!(t.unix_ns() > 1_700_000_000_000_000_000);
        assert_eq!(TestStart::parse_rfc3339(&t.rfc3339()), Some(t));
    }
}
