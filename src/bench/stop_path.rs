//! How a running test is stopped, as the sequencers ([`super::run_test`],
//! [`super::run_im_sweep`]) see it.
//!
//! Every test of `motorbench run` and the daemon runs under the safety
//! supervisor ([`crate::session`]), where every stop goes through the
//! supervisor, whichever layer sees the reason first: a check of the
//! sequencer's [`super::SafetyMonitor`] that fails before the supervisor's
//! own (its monitor may lack the sweep's heating budget) is handed to the
//! supervisor, which commands the safe state,
//! latches the rig and records the stop; the sequencer then records on
//! until the supervisor ends the stream after a sample read in the safe
//! state, so the record shows the rig safe.
//!
//! A sequencer driven on its own (the sequencer's tests, a library user's
//! own loop) stops on an operator flag instead (raised at any time: the
//! sequencer waits on it beside each read) or on a fault it sees, and
//! commands the safe state itself.

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
    /// The operator's stop flag of an unsupervised test, for the
    /// sequencer to wait on beside each read (under the supervisor, stops
    /// arrive as the stream's error).
    pub fn operator_flag(&self) -> Option<watch::Receiver<bool>> {
        match self {
            StopPath::Unsupervised(flag) => Some((*flag).clone()),
            StopPath::Supervised(_) => None,
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
