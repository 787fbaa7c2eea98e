//! How a running test is stopped, as the sequencers ([`super::run_test`],
//! [`super::run_im_sweep`]) see it.
//!
//! Without a supervisor (`motorbench run`) the sequencer stops on an
//! operator flag or on a fault it sees, and commands the safe state
//! itself. Under the daemon's safety supervisor every stop goes through
//! the supervisor, whichever layer sees the reason first: a limit the
//! sequencer's own check finds before the supervisor's (the two estimate
//! speed differently, the induction-machine sweep has its own current and
//! I²t bounds) is handed to the supervisor, which commands the safe state,
//! latches the rig and records the stop; the sequencer then records on
//! until the supervisor ends the stream after a sample read in the safe
//! state, so the record shows the rig safe.

use tokio::sync::watch;

use super::{StopCause, SupervisorHandle};

/// Where a sequencer's stops come from and go to. See the module docs.
/// Built from an operator flag (`&watch::Receiver<bool>`) or from the
/// supervisor's handle (`&SupervisorHandle`).
#[derive(Debug, Clone, Copy)]
pub enum StopPath<'a> {
    /// No supervisor: `true` on the flag is an operator stop; faults are
    /// the sequencer's to act on.
    Unsupervised(&'a watch::Receiver<bool>),
    /// Under the safety supervisor: stops arrive as the stream's error,
    /// and faults the sequencer sees first are handed to it.
    Supervised(&'a SupervisorHandle),
}

impl<'a> From<&'a watch::Receiver<bool>> for StopPath<'a> {
    fn from(flag: &'a watch::Receiver<bool>) -> StopPath<'a> {
        StopPath::Unsupervised(flag)
    }
}

impl<'a> From<&'a SupervisorHandle> for StopPath<'a> {
    fn from(handle: &'a SupervisorHandle) -> StopPath<'a> {
        StopPath::Supervised(handle)
    }
}

impl StopPath<'_> {
    /// An operator asked an unsupervised test to stop.
    pub fn operator_stop(&self) -> bool {
        match self {
            StopPath::Unsupervised(flag) => *flag.borrow(),
            StopPath::Supervised(_) => false,
        }
    }

    /// Hand `cause`, seen by the sequencer in the reading at data time
    /// `t_ns`, to the supervisor. `true` once the supervisor has commanded
    /// the safe state and latched the rig (or had already stopped the
    /// test); `false` when there is no supervisor (or it has ended), and
    /// the sequencer must command the safe state itself.
    pub async fn trip(&self, cause: StopCause, t_ns: u64) -> bool {
        match self {
            StopPath::Unsupervised(_) => false,
            StopPath::Supervised(handle) => handle.trip(cause, t_ns).await.is_some(),
        }
    }
}
