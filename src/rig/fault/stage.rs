//! [`FaultyStage`]: a power stage with the stage faults of a `[[fault]]`
//! plan: a supply that limits its current, or a stage that acknowledges
//! the safe command (`ignore_safe_state`), and the output disable too
//! (`ignore_disable`), without acting on them — the case the supervisor's
//! escalation (`bench/escalation.rs`) is for. The faults act on the test
//! time the faulty sensors keep ([`FaultClock`]).

use std::time::Duration;

use async_trait::async_trait;
use motorbench_drivers::{DriverError, PowerStage, StageCapabilities};

use super::FaultClock;
use crate::config::{Fault, FaultKind};

/// The power stage with faults. See the module docs.
pub struct FaultyStage {
    inner: Box<dyn PowerStage>,
    faults: Vec<Fault>,
    clock: FaultClock,
    /// The current limit the fault put in place, A.
    limited: Option<f64>,
    /// The limit the bench asked for, A.
    asked: Option<f64>,
}

impl FaultyStage {
    /// `inner` with `faults` (stage faults), on `clock`'s time.
    pub fn new(inner: Box<dyn PowerStage>, faults: Vec<Fault>, clock: FaultClock) -> FaultyStage {
        FaultyStage {
            inner,
            faults,
            clock,
            limited: None,
            asked: None,
        }
    }

    /// A fault of `kind` acts now.
    fn acting(&self, kinds: &[FaultKind]) -> Option<&Fault> {
        let t = self.clock.t_s();
        self.faults
            .iter()
            .find(|f| kinds.contains(&f.kind) && f.active(t))
    }

    /// Put a current limit that has started in place (or lift one that
    /// has ended): the supply limits at the smaller of the fault's value
    /// and what the bench asked for.
    async fn limit_current(&mut self) -> Result<(), DriverError> {
        let want = self
            .acting(&[FaultKind::CurrentLimit])
            .and_then(|f| f.value)
            .map(|v| self.asked.map_or(v, |a| a.min(v)));
        if want == self.limited {
            return Ok(());
        }
        self.limited = want;
        match want.or(self.asked) {
            Some(a) => self.inner.set_current_limit(a).await,
            None => Ok(()),
        }
    }
}

#[async_trait]
impl PowerStage for FaultyStage {
    fn id(&self) -> &str {
        self.inner.id()
    }

    fn capabilities(&self) -> StageCapabilities {
        self.inner.capabilities()
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        self.limit_current().await?;
        self.inner.set_setpoint(value).await
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        if !enabled && self.acting(&[FaultKind::IgnoreDisable]).is_some() {
            // Acknowledged, not acted on.
            return Ok(());
        }
        self.limit_current().await?;
        self.inner.set_output_enabled(enabled).await
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        if self
            .acting(&[FaultKind::IgnoreSafeState, FaultKind::IgnoreDisable])
            .is_some()
        {
            return Ok(());
        }
        self.inner.safe_state().await
    }

    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        self.inner.read_output_enabled().await
    }

    async fn set_current_limit(&mut self, amperes: f64) -> Result<(), DriverError> {
        self.asked = Some(amperes);
        self.limited = None;
        let limit = self
            .acting(&[FaultKind::CurrentLimit])
            .and_then(|f| f.value)
            .map_or(amperes, |v| amperes.min(v));
        if limit < amperes {
            self.limited = Some(limit);
        }
        self.inner.set_current_limit(limit).await
    }

    async fn set_frequency(&mut self, hz: f64) -> Result<(), DriverError> {
        self.inner.set_frequency(hz).await
    }

    fn heartbeat_timeout(&self) -> Option<Duration> {
        self.inner.heartbeat_timeout()
    }

    async fn heartbeat(&mut self) -> Result<(), DriverError> {
        self.inner.heartbeat().await
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;
    use crate::machine::dc::sim_rig;

    fn stage(
        kind: FaultKind,
        value: Option<f64>,
    ) -> (FaultyStage, crate::machine::dc::SimPowerStage) {
        let cfg = Config::embedded_default();
        let (sim, _) = sim_rig(cfg.backend.simulated().unwrap(), 2000.0, false).unwrap();
        let fault = Fault {
            index: 0,
            kind,
            at_s: 0.0,
            for_s: None,
            target: None,
            value,
        };
        let faulty = FaultyStage::new(Box::new(sim.clone()), vec![fault], FaultClock::default());
        (faulty, sim)
    }

    #[tokio::test]
    async fn a_stage_that_ignores_the_safe_command_stays_enabled_and_says_so() {
        let (mut s, sim) = stage(FaultKind::IgnoreSafeState, None);
        s.set_output_enabled(true).await.unwrap();
        s.set_setpoint(60.0).await.unwrap();
        s.safe_state().await.unwrap();
        assert!(sim.output_enabled());
        assert_eq!(s.read_output_enabled().await, Ok(Some(true)));
        // The output disable still works.
        s.set_output_enabled(false).await.unwrap();
        assert_eq!(s.read_output_enabled().await, Ok(Some(false)));

        let (mut s, sim) = stage(FaultKind::IgnoreDisable, None);
        s.set_output_enabled(true).await.unwrap();
        s.safe_state().await.unwrap();
        s.set_output_enabled(false).await.unwrap();
        assert!(sim.output_enabled());
        assert_eq!(s.read_output_enabled().await, Ok(Some(true)));
    }
}
