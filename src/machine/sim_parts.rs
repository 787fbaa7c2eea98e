//! What the simulated rigs of both machines share: the lock on the plant
//! their simulated devices hold together, and the profile checks of a
//! simulated device served behind its register map.

use std::sync::{Mutex, MutexGuard};

use motorbench_drivers::modbus::{DeviceProfile, StageMap};

use crate::rig::ServeError;

/// The plant behind `plant`'s lock. A panic while holding the lock cannot
/// leave the plant half-updated in a way that matters more than stopping:
/// keep going with its state.
pub(crate) fn lock_plant<T>(plant: &Mutex<T>) -> MutexGuard<'_, T> {
    plant.lock().unwrap_or_else(|e| e.into_inner())
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
