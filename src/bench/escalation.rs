//! What the supervisor does when a stage's output stays on after the safe
//! command: a stage that acknowledged the command without acting on it.
//!
//! After a safe command that the stage acknowledged, the supervisor reads
//! back whether its output is still enabled
//! ([`PowerStage::read_output_enabled`]; a stage that cannot tell, or
//! whose read-back fails, is taken at its word). An output still on is
//! commanded off (the output disable alone); one still on after that gets
//! the configured last resort (`supervisor.last_resort_command`, e.g. a
//! program that opens a contactor or trips the e-stop loop). Every step
//! is one line of the [`Escalation`], recorded as an abort event.

use std::time::Duration;

use motorbench_drivers::PowerStage;

use crate::config::LastResort;

/// The longest a last-resort command may run before it counts as failed.
pub const LAST_RESORT_TIMEOUT: Duration = Duration::from_secs(10);

/// What one stage's escalation did. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct Escalation {
    /// Each step, for a person and the record (empty: the stage's output
    /// was off after the safe command, or it cannot tell).
    pub steps: Vec<String>,
    /// `Err` when the stage may still be driving the machine: its output
    /// is on after the disable and no last resort ran successfully.
    pub outcome: Result<(), String>,
}

impl Default for Escalation {
    /// Nothing done, nothing wrong.
    fn default() -> Escalation {
        Escalation {
            steps: Vec::new(),
            outcome: Ok(()),
        }
    }
}

/// Escalate on `stage` (just commanded to its safe state) as the module
/// docs say, with `last_resort` as the final step.
pub async fn escalate(stage: &mut dyn PowerStage, last_resort: Option<&LastResort>) -> Escalation {
    let id = stage.id().to_string();
    // A stage that cannot tell (or whose link failed after the command
    // went through) is taken at its word.
    if !matches!(stage.read_output_enabled().await, Ok(Some(true))) {
        return Escalation::default();
    }
    let mut steps = vec![format!(
        "escalation: {id}: output still enabled after the safe command: disabling the output"
    )];
    let disabled = stage.set_output_enabled(false).await;
    let still_on = !matches!(
        (&disabled, stage.read_output_enabled().await),
        (Ok(()), Ok(Some(false) | None))
    );
    if !still_on {
        steps.push(format!("escalation: {id}: output disabled"));
        return Escalation {
            steps,
            outcome: Ok(()),
        };
    }
    let why = match disabled {
        Err(e) => format!("the output disable failed ({e})"),
        Ok(()) => "output still enabled after the output disable".into(),
    };
    let Some(last) = last_resort else {
        steps.push(format!(
            "escalation: {id}: {why}, and no supervisor.last_resort_command is configured: THE STAGE MAY STILL BE DRIVING THE MACHINE"
        ));
        return Escalation {
            steps,
            outcome: Err(format!("{id}: {why}; no last resort configured")),
        };
    };
    let command = last.argv.join(" ");
    steps.push(format!(
        "escalation: {id}: {why}: running the last resort `{command}`"
    ));
    let outcome = match run(last).await {
        Ok(()) => {
            steps.push(format!("escalation: {id}: last resort `{command}` done"));
            Ok(())
        }
        Err(e) => {
            steps.push(format!(
                "escalation: {id}: last resort `{command}` FAILED: {e}: THE STAGE MAY STILL BE DRIVING THE MACHINE"
            ));
            Err(format!("{id}: {why}; last resort failed: {e}"))
        }
    };
    Escalation { steps, outcome }
}

/// Run the last-resort program to its end (within
/// [`LAST_RESORT_TIMEOUT`]); `Err` unless it exits with success.
async fn run(last: &LastResort) -> Result<(), String> {
    let (program, args) = last
        .argv
        .split_first()
        .ok_or_else(|| "no program".to_string())?;
    let mut cmd = tokio::process::Command::new(program);
    cmd.args(args)
        .stdin(std::process::Stdio::null())
        .kill_on_drop(true);
    match tokio::time::timeout(LAST_RESORT_TIMEOUT, cmd.status()).await {
        Err(_) => Err(format!(
            "did not end within {} s",
            LAST_RESORT_TIMEOUT.as_secs()
        )),
        Ok(Err(e)) => Err(format!("cannot run it: {e}")),
        Ok(Ok(status)) if status.success() => Ok(()),
        Ok(Ok(status)) => Err(format!("it ended with {status}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Config, Fault, FaultKind};
    use crate::machine::dc::sim_rig;
    use crate::rig::fault::{FaultClock, FaultyStage};

    fn stage(kind: Option<FaultKind>) -> FaultyStage {
        let cfg = Config::embedded_default();
        let (sim, _) = sim_rig(cfg.backend.simulated().unwrap(), 2000.0, false).unwrap();
        let faults = kind
            .map(|kind| Fault {
                index: 0,
                kind,
                at_s: 0.0,
                for_s: None,
                target: None,
                value: None,
            })
            .into_iter()
            .collect();
        FaultyStage::new(Box::new(sim), faults, FaultClock::default())
    }

    async fn after_safe(kind: Option<FaultKind>, last: Option<&LastResort>) -> Escalation {
        let mut s = stage(kind);
        s.set_output_enabled(true).await.unwrap();
        s.safe_state().await.unwrap();
        escalate(&mut s, last).await
    }

    #[tokio::test]
    async fn each_step_is_taken_only_when_the_one_before_did_not_work() {
        // A stage that obeys: nothing to do.
        assert_eq!(after_safe(None, None).await, Escalation::default());
        // Ignores the safe command: the output disable does it.
        let e = after_safe(Some(FaultKind::IgnoreSafeState), None).await;
        assert_eq!(e.outcome, Ok(()));
        assert_eq!(e.steps.len(), 2, "{:?}", e.steps);
        assert!(e.steps[1].ends_with("output disabled"));
        // Ignores the disable too, nothing configured: the rig is not safe.
        let e = after_safe(Some(FaultKind::IgnoreDisable), None).await;
        assert!(e.outcome.is_err());
        assert!(e.steps[1].contains("no supervisor.last_resort_command"));
        // The last resort runs; its failure is reported.
        let ok = LastResort {
            argv: vec!["true".into()],
        };
        let e = after_safe(Some(FaultKind::IgnoreDisable), Some(&ok)).await;
        assert_eq!(e.outcome, Ok(()));
        assert!(
            e.steps[2].ends_with("last resort `true` done"),
            "{:?}",
            e.steps
        );
        let bad = LastResort {
            argv: vec!["false".into()],
        };
        let e = after_safe(Some(FaultKind::IgnoreDisable), Some(&bad)).await;
        assert!(e.outcome.is_err());
        assert!(e.steps[2].contains("FAILED"), "{:?}", e.steps);
    }
}
