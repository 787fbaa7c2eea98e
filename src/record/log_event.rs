//! Bench events as `/bench/event` messages, in either contract version.
//!
//! Version 1 wrote `motorbench.Event` (`{"level": "info"|"warn"|"abort",
//! "message": …}`), which Foxglove's Log panel does not show. Version 2
//! writes the shape of Foxglove's `foxglove.Log` (schema name
//! `foxglove.Log`): `timestamp` (`{sec, nsec}`, the message's wall-clock
//! time), `level` as Foxglove's number (info → 2 INFO, warn → 3 WARNING,
//! abort → 4 ERROR), `message`, `name` (`motorbench`), `file` and `line`
//! (empty and 0: the event has no source line a user could open).
//!
//! The reader takes either shape whatever the version says, so a file
//! that mixes them (none is written) still reads; Foxglove levels the bench
//! never writes map to the nearest: UNKNOWN and DEBUG to info, FATAL to
//! abort.

use serde::{Deserialize, Serialize};

use super::types::{Event, EventLevel};

/// The `name` of every event motorbench writes.
pub const LOG_NAME: &str = "motorbench";

/// Foxglove's `LogLevel` numbers.
const INFO: u8 = 2;
const WARNING: u8 = 3;
const ERROR: u8 = 4;

/// A `foxglove.Log` time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct LogTime {
    /// Whole seconds since the Unix epoch.
    pub sec: u64,
    /// Nanoseconds within the second, 0..=999 999 999.
    pub nsec: u32,
}

impl LogTime {
    /// The time `unix_ns` ns after the Unix epoch.
    pub fn from_unix_ns(unix_ns: u64) -> LogTime {
        LogTime {
            sec: unix_ns / 1_000_000_000,
            nsec: (unix_ns % 1_000_000_000) as u32,
        }
    }
}

/// A version-2 `/bench/event` message: the shape of `foxglove.Log`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LogMessage<'a> {
    /// When it happened, wall clock.
    pub timestamp: LogTime,
    /// Foxglove's level number.
    pub level: u8,
    /// What happened, for a person.
    pub message: &'a str,
    /// Always [`LOG_NAME`].
    pub name: &'static str,
    /// Always empty.
    pub file: &'static str,
    /// Always 0.
    pub line: u32,
}

impl<'a> LogMessage<'a> {
    /// `event` at `unix_ns`.
    pub fn new(event: &'a Event, unix_ns: u64) -> LogMessage<'a> {
        LogMessage {
            timestamp: LogTime::from_unix_ns(unix_ns),
            level: match event.level {
                EventLevel::Info => INFO,
                EventLevel::Warn => WARNING,
                EventLevel::Abort => ERROR,
            },
            message: &event.message,
            name: LOG_NAME,
            file: "",
            line: 0,
        }
    }
}

/// A level as either version writes it.
#[derive(Debug, Deserialize)]
#[serde(untagged)]
enum AnyLevel {
    /// Version 1: the contract's name.
    Named(EventLevel),
    /// Version 2: Foxglove's number.
    Number(u8),
}

/// A `/bench/event` message of either version; other keys are ignored.
#[derive(Debug, Deserialize)]
pub struct AnyEvent {
    level: AnyLevel,
    message: String,
}

impl From<AnyEvent> for Event {
    fn from(e: AnyEvent) -> Event {
        let level = match e.level {
            AnyLevel::Named(level) => level,
            AnyLevel::Number(n) if n <= INFO => EventLevel::Info,
            AnyLevel::Number(WARNING) => EventLevel::Warn,
            AnyLevel::Number(_) => EventLevel::Abort,
        };
        Event {
            level,
            message: e.message,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read(text: &str) -> Event {
        serde_json::from_str::<AnyEvent>(text).unwrap().into()
    }

    #[test]
    fn every_level_round_trips_through_the_log_shape() {
        for level in [EventLevel::Info, EventLevel::Warn, EventLevel::Abort] {
            let event = Event {
                level,
                message: "stopped: \"limit\"".into(),
            };
            let text = serde_json::to_string(&LogMessage::new(&event, 1_500_000_000_250)).unwrap();
            assert_eq!(read(&text), event, "{text}");
        }
    }

    #[test]
    fn the_log_shape_is_foxglove_s() {
        let event = Event {
            level: EventLevel::Warn,
            message: "hot".into(),
        };
        let v = serde_json::to_value(LogMessage::new(&event, 1_796_312_930_000_000_007)).unwrap();
        assert_eq!(
            v,
            serde_json::json!({"timestamp": {"sec": 1_796_312_930u64, "nsec": 7}, "level": 3,
                "message": "hot", "name": "motorbench", "file": "", "line": 0})
        );
    }

    #[test]
    fn version_1_events_and_foreign_levels_read() {
        assert_eq!(
            read(r#"{"level":"abort","message":"x"}"#).level,
            EventLevel::Abort
        );
        assert_eq!(read(r#"{"level":1,"message":"x"}"#).level, EventLevel::Info);
        assert_eq!(
            read(r#"{"level":5,"message":"x"}"#).level,
            EventLevel::Abort
        );
        assert!(serde_json::from_str::<AnyEvent>(r#"{"level":"loud","message":"x"}"#).is_err());
        assert!(serde_json::from_str::<AnyEvent>(r#"{"level":2}"#).is_err());
    }
}
