//! The [`PowerStage`] trait: anything that drives the machine under test.

use std::time::Duration;

use async_trait::async_trait;

use crate::DriverError;

/// What a power stage can do beyond the required operations.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StageCapabilities {
    /// The stage accepts a current limit.
    pub current_limit: bool,
    /// Largest set point magnitude the stage accepts, in its own unit.
    pub max_setpoint: f64,
}

/// A controllable output: an armature supply, a VFD, a dynamometer.
///
/// The required operations are a set point, an output enable and the safe
/// state. `safe_state` must work from any state, including after an error,
/// and must leave the output disabled with a zero set point.
#[async_trait]
pub trait PowerStage: Send {
    /// Driver id, used as `source` in recorded channel metadata.
    fn id(&self) -> &str;

    /// What this stage supports.
    fn capabilities(&self) -> StageCapabilities;

    /// Command a new set point (volts for a DC supply, rad/s for a
    /// dynamometer, …). The stage may slew towards it.
    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError>;

    /// Enable or disable the output.
    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError>;

    /// Put the stage in its safe state: set point zero, output disabled.
    async fn safe_state(&mut self) -> Result<(), DriverError>;

    /// Limit the output current (amperes). Optional.
    async fn set_current_limit(&mut self, _amperes: f64) -> Result<(), DriverError> {
        Err(DriverError::Unsupported {
            device: self.id().to_string(),
            what: "a current limit",
        })
    }

    /// Command the output frequency (hertz), for a stage whose output is
    /// alternating (a VFD feeding a machine). Optional: a stage without
    /// one refuses with [`DriverError::Unsupported`].
    async fn set_frequency(&mut self, _hz: f64) -> Result<(), DriverError> {
        Err(DriverError::Unsupported {
            device: self.id().to_string(),
            what: "a frequency command",
        })
    }

    /// Read back whether the output is enabled, as the stage itself
    /// reports it (not as last commanded): `Some(true)` after a safe
    /// command means the stage did not act on it. Optional: `None` (the
    /// default) when the stage cannot tell.
    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        Ok(None)
    }

    /// The keep-alive timeout of the stage's heartbeat, when it has one:
    /// once armed by a first [`PowerStage::heartbeat`], a stage that is not
    /// petted again within this time goes to its safe state by itself, so a
    /// dead or hung controller leaves a safe rig. `None` (the default): no
    /// heartbeat.
    fn heartbeat_timeout(&self) -> Option<Duration> {
        None
    }

    /// Pet the heartbeat (arming it on the first call). Call it only while
    /// the controller is healthy. Optional.
    async fn heartbeat(&mut self) -> Result<(), DriverError> {
        Err(DriverError::Unsupported {
            device: self.id().to_string(),
            what: "a heartbeat",
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stage with only the required operations.
    struct Plain;

    #[async_trait]
    impl PowerStage for Plain {
        fn id(&self) -> &str {
            "plain"
        }
        fn capabilities(&self) -> StageCapabilities {
            StageCapabilities::default()
        }
        async fn set_setpoint(&mut self, _: f64) -> Result<(), DriverError> {
            Ok(())
        }
        async fn set_output_enabled(&mut self, _: bool) -> Result<(), DriverError> {
            Ok(())
        }
        async fn safe_state(&mut self) -> Result<(), DriverError> {
            Ok(())
        }
    }

    #[tokio::test]
    async fn optional_capabilities_default_to_unsupported() {
        let mut stage = Plain;
        assert_eq!(stage.heartbeat_timeout(), None);
        let e = stage.heartbeat().await.unwrap_err();
        assert_eq!(e.to_string(), "plain does not support a heartbeat");
        let e = stage.set_current_limit(1.0).await.unwrap_err();
        assert!(matches!(e, DriverError::Unsupported { .. }));
        let e = stage.set_frequency(12.5).await.unwrap_err();
        assert_eq!(e.to_string(), "plain does not support a frequency command");
        assert_eq!(stage.read_output_enabled().await, Ok(None));
    }
}
