//! The one check of a power stage's set point against its range, for
//! every stage of every machine (the drives wrapped for a test, the
//! simulated stages): a set point that is not a finite number in range is
//! refused as a device error naming the stage, before anything is
//! written.

use motorbench_drivers::DriverError;

/// Refuse `value` unless it is finite and in `[0, max · slack]`; the
/// error names `device`, the quantity `what` and its `unit`, and shows
/// the range as `[0, max]` (a simulated stage accepts a rounding `slack`
/// over its rating; a real one passes 1).
pub(crate) fn check_setpoint(
    device: &str,
    what: &str,
    unit: &str,
    value: f64,
    max: f64,
    slack: f64,
) -> Result<(), DriverError> {
    if value.is_finite() && (0.0..=max * slack).contains(&value) {
        Ok(())
    } else {
        Err(DriverError::Device {
            device: device.to_string(),
            reason: format!("{what} set point {value} {unit} outside [0, {max}] {unit}"),
        })
    }
}

/// Refuse a supply frequency `hz` unless it is finite and in
/// `(0, rated · slack]`; the error names `device` and shows the range as
/// `(0, rated]`.
pub(crate) fn check_frequency(
    device: &str,
    hz: f64,
    rated: f64,
    slack: f64,
) -> Result<(), DriverError> {
    if hz.is_finite() && hz > 0.0 && hz <= rated * slack {
        Ok(())
    } else {
        Err(DriverError::Device {
            device: device.to_string(),
            reason: format!("frequency {hz} Hz outside (0, {rated}] Hz"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_set_point_in_range_passes_and_one_outside_is_refused_by_name() {
        assert!(check_setpoint("vfd", "voltage", "V", 400.0, 400.0, 1.0).is_ok());
        assert!(check_setpoint("vfd", "voltage", "V", 400.02, 400.0, 1.0001).is_ok());
        let e = check_setpoint("vfd", "voltage", "V", 401.0, 400.0, 1.0).unwrap_err();
        assert_eq!(
            e.to_string(),
            DriverError::Device {
                device: "vfd".into(),
                reason: "voltage set point 401 V outside [0, 400] V".into(),
            }
            .to_string()
        );
        assert!(check_setpoint("vfd", "voltage", "V", f64::NAN, 400.0, 1.0).is_err());
        assert!(check_setpoint("vfd", "voltage", "V", -1.0, 400.0, 1.0).is_err());
    }

    #[test]
    fn a_frequency_must_be_positive_and_at_most_the_rated_one() {
        assert!(check_frequency("vfd", 25.0, 50.0, 1.0).is_ok());
        assert!(check_frequency("vfd", 0.0, 50.0, 1.0).is_err());
        assert!(check_frequency("vfd", 50.004, 50.0, 1.0001).is_ok());
        assert!(check_frequency("vfd", 51.0, 50.0, 1.0).is_err());
    }
}
