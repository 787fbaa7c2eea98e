//! Typed driver errors: the kind decides retry versus safe state.

use thiserror::Error;

/// What went wrong talking to a device.
///
/// `Link` and `Timeout` mean the device could not be reached (a pulled
/// cable, a dead peer); `Device` means it answered and refused. Callers put
/// the rig in its safe state on any of them during a test.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum DriverError {
    /// The transport failed: the device was not reached.
    #[error("link to {device} failed: {reason}")]
    Link {
        /// Driver id of the device.
        device: String,
        /// What the transport reported.
        reason: String,
    },
    /// The device answered with an error or refused the request.
    #[error("{device} refused the request: {reason}")]
    Device {
        /// Driver id of the device.
        device: String,
        /// What the device reported.
        reason: String,
    },
    /// No answer within the call's deadline.
    #[error("{device} did not answer within {timeout_ms} ms")]
    Timeout {
        /// Driver id of the device.
        device: String,
        /// The deadline that passed.
        timeout_ms: u64,
    },
    /// The device cannot do what was asked (an optional capability).
    #[error("{device} does not support {what}")]
    Unsupported {
        /// Driver id of the device.
        device: String,
        /// The capability that was asked for.
        what: &'static str,
    },
    /// The stream of samples has ended (the device closed it).
    #[error("{device}: sample stream ended")]
    Ended {
        /// Driver id of the device.
        device: String,
    },
}

impl DriverError {
    /// True when the device was not reached at all (link or timeout).
    pub fn is_link_failure(&self) -> bool {
        matches!(self, DriverError::Link { .. } | DriverError::Timeout { .. })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_failures_are_kept_apart_from_device_refusals() {
        let link = DriverError::Link {
            device: "psu".into(),
            reason: "broken pipe".into(),
        };
        let timeout = DriverError::Timeout {
            device: "psu".into(),
            timeout_ms: 100,
        };
        let refused = DriverError::Device {
            device: "psu".into(),
            reason: "illegal data address".into(),
        };
        assert!(link.is_link_failure() && timeout.is_link_failure());
        assert!(!refused.is_link_failure());
        assert_eq!(timeout.to_string(), "psu did not answer within 100 ms");
    }
}
