//! What the simulated rigs of both machines share: the lock on the plant
//! their simulated devices hold together, the plant on the wall clock
//! that a served rig's devices answer from, and the profile checks of a
//! simulated device served behind its register map.

use std::sync::{Mutex, MutexGuard};

use motorbench_drivers::modbus::{DeviceProfile, StageMap};
use motorbench_drivers::SampleBatch;

use crate::rig::ServeError;

/// The plant behind `plant`'s lock. A panic while holding the lock cannot
/// leave the plant half-updated in a way that matters more than stopping:
/// keep going with its state.
pub(crate) fn lock_plant<T>(plant: &Mutex<T>) -> MutexGuard<'_, T> {
    plant.lock().unwrap_or_else(|e| e.into_inner())
}

/// A simulated plant on the wall clock, behind a served rig's devices:
/// every request first advances it to now in steps of its own period.
pub(crate) trait ServedPlant {
    /// Advance the plant to now.
    fn catch_up(&mut self);

    /// The sensors' latest sample, none before the first step.
    fn last(&self) -> Option<&SampleBatch>;

    /// The latest sample's value of the channel `ch`, 0 where there is
    /// none.
    fn reading(&self, ch: usize) -> f64 {
        self.last().and_then(|b| b.value(ch)).unwrap_or(0.0)
    }
}

/// The plant locked and advanced to now, as every request finds it.
pub(crate) fn plant_now<P: ServedPlant>(plant: &Mutex<P>) -> MutexGuard<'_, P> {
    let mut p = lock_plant(plant);
    p.catch_up();
    p
}

/// Why the simulated rig cannot serve a device of `profile`: the profile
/// lacks `what`.
pub(crate) fn missing(profile: &DeviceProfile, what: &str) -> ServeError {
    ServeError::MissingRegister {
        profile: profile.name.clone(),
        register: what.into(),
    }
}

/// The `[power_stage]` section of `profile`, which a served stage answers
/// on.
pub(crate) fn power_stage_map(profile: &DeviceProfile) -> Result<&StageMap, ServeError> {
    profile
        .power_stage
        .as_ref()
        .ok_or_else(|| missing(profile, "[power_stage] section"))
}
