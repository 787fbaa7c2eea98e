//! Test plans as a list of steps: voltage levels and coast-downs.

use crate::config::Plan;
use crate::record::SegmentKind;

/// One segment of a plan.
#[derive(Debug, Clone, PartialEq)]
pub enum PlanStep {
    /// Step the armature voltage to `volts` and hold until settled.
    Level {
        /// Target armature voltage, V.
        volts: f64,
        /// Segment label.
        label: String,
    },
    /// Open the armature and record the decay to rest.
    Coastdown {
        /// Segment label.
        label: String,
    },
}

impl PlanStep {
    /// The segment kind this step records.
    pub fn kind(&self) -> SegmentKind {
        match self {
            PlanStep::Level { .. } => SegmentKind::DcStep,
            PlanStep::Coastdown { .. } => SegmentKind::DcCoastdown,
        }
    }

    /// The segment label.
    pub fn label(&self) -> &str {
        match self {
            PlanStep::Level { label, .. } | PlanStep::Coastdown { label } => label,
        }
    }
}

/// The steps of a plan, each one segment, starting from rest at 0 V.
pub fn plan_steps(plan: &Plan) -> Vec<PlanStep> {
    let (levels, coastdown) = match plan {
        Plan::DcStep { levels, coastdown } => (levels.clone(), *coastdown),
        Plan::DcCoastdown { from } => (vec![*from], true),
    };
    let mut steps = Vec::new();
    let mut previous = 0.0;
    for (n, &volts) in levels.iter().enumerate() {
        let suffix = if n == 0 { " (from rest)" } else { "" };
        steps.push(PlanStep::Level {
            volts,
            label: format!("{previous} V → {volts} V{suffix}"),
        });
        previous = volts;
    }
    if coastdown {
        steps.push(PlanStep::Coastdown {
            label: format!("coast-down from {previous} V"),
        });
    }
    steps
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn staircase_labels_each_step_and_ends_with_coastdown() {
        let steps = plan_steps(&Plan::DcStep {
            levels: vec![60.0, 248.0, 60.0],
            coastdown: true,
        });
        let labels: Vec<_> = steps.iter().map(|s| s.label().to_string()).collect();
        assert_eq!(
            labels,
            [
                "0 V → 60 V (from rest)",
                "60 V → 248 V",
                "248 V → 60 V",
                "coast-down from 60 V"
            ]
        );
        assert_eq!(steps[3].kind(), SegmentKind::DcCoastdown);
    }

    #[test]
    fn coastdown_plan_runs_up_first() {
        let steps = plan_steps(&Plan::DcCoastdown { from: 248.0 });
        assert_eq!(steps.len(), 2);
        assert!(matches!(steps[0], PlanStep::Level { volts, .. } if volts == 248.0));
    }
}
