//! The protocol faults of one served Modbus device ([`ProtocolFaults`]),
//! asked before every answer it gives (the drivers' [`Interference`]
//! hook): no answer while a `bus_timeout` lasts or once a `disconnect`
//! has happened, an exception reply while a `modbus_exception` lasts. The
//! line faults of an RTU device (`crc_error`, `garbage`) act on its bytes
//! instead ([`super::FaultyLine`]). All on the served plant's clock: the
//! time since the rig was served.

use std::sync::Arc;
use std::time::Instant;

use motorbench_drivers::modbus::server::{Interfere, Interference};

use crate::config::{Fault, FaultKind};

/// The protocol faults of one served device. See the module docs.
#[derive(Debug, Clone)]
pub struct ProtocolFaults {
    faults: Arc<Vec<Fault>>,
    epoch: Instant,
}

impl ProtocolFaults {
    /// The faults of `plan_faults` that target `device`, on a clock that
    /// starts at `epoch`; `None` when none does.
    pub fn for_device(
        plan_faults: &[Fault],
        device: &str,
        epoch: Instant,
    ) -> Option<ProtocolFaults> {
        let mine: Vec<Fault> = plan_faults
            .iter()
            .filter(|f| f.kind.on_protocol() && f.target.as_deref() == Some(device))
            .cloned()
            .collect();
        (!mine.is_empty()).then(|| ProtocolFaults {
            faults: Arc::new(mine),
            epoch,
        })
    }

    /// Time since the rig was served, s.
    fn t_s(&self) -> f64 {
        self.epoch.elapsed().as_secs_f64()
    }

    /// The fault of `kind` acting now, if any.
    pub fn acting(&self, kind: FaultKind) -> Option<&Fault> {
        let t = self.t_s();
        self.faults.iter().find(|f| f.kind == kind && f.active(t))
    }

    /// Has a fault of `kind` (there is one, `at_s` from the start).
    pub fn has(&self, kind: FaultKind) -> bool {
        self.faults.iter().any(|f| f.kind == kind)
    }

    /// When the device's link goes away for good, s from the start.
    pub fn disconnect_at(&self) -> Option<f64> {
        self.faults
            .iter()
            .find(|f| f.kind == FaultKind::Disconnect)
            .map(|f| f.at_s)
    }
}

#[cfg(test)]
impl ProtocolFaults {
    /// One fault of `kind` on the device `sensors`, from the start and
    /// for good (the unit tests' fixture).
    pub(crate) fn one(kind: FaultKind) -> ProtocolFaults {
        let f = Fault {
            index: 0,
            kind,
            at_s: 0.0,
            for_s: None,
            target: Some("sensors".into()),
            value: None,
        };
        ProtocolFaults::for_device(&[f], "sensors", Instant::now()).expect("a fault on sensors")
    }
}

impl Interference for ProtocolFaults {
    fn interfere(&self) -> Option<Interfere> {
        if self.acting(FaultKind::Disconnect).is_some()
            || self.acting(FaultKind::BusTimeout).is_some()
        {
            return Some(Interfere::Silence);
        }
        self.acting(FaultKind::ModbusException).map(|f| {
            // Validated: an exception code 1 to 255.
            Interfere::Exception(f.value.map_or(4, |v| v as u8))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fault(kind: FaultKind, at_s: f64, for_s: Option<f64>, value: Option<f64>) -> Fault {
        Fault {
            index: 0,
            kind,
            at_s,
            for_s,
            target: Some("sensors".into()),
            value,
        }
    }

    #[test]
    fn a_device_is_silent_or_refuses_in_its_fault_windows_only() {
        let now = Instant::now();
        let faults = [
            fault(FaultKind::ModbusException, 0.0, Some(1e6), Some(6.0)),
            fault(FaultKind::Nan, 0.0, None, None),
        ];
        let p = ProtocolFaults::for_device(&faults, "sensors", now).unwrap();
        assert_eq!(p.interfere(), Some(Interfere::Exception(6)));
        assert!(ProtocolFaults::for_device(&faults, "power_stage", now).is_none());
        let later = [fault(FaultKind::BusTimeout, 1e6, Some(1.0), None)];
        let p = ProtocolFaults::for_device(&later, "sensors", now).unwrap();
        assert_eq!(p.interfere(), None);
        let gone = [fault(FaultKind::Disconnect, 0.0, None, None)];
        let p = ProtocolFaults::for_device(&gone, "sensors", now).unwrap();
        assert_eq!(p.interfere(), Some(Interfere::Silence));
        assert_eq!(p.disconnect_at(), Some(0.0));
    }
}
