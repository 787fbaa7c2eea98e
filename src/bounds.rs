//! Practical bounds on every number from outside (a configuration file,
//! the API's test override, a device profile, a CSV file) that sizes an
//! allocation, a loop or a wait.
//!
//! A number past one of these is refused where it is read, with the file
//! and key (or the request's field) named, instead of becoming a
//! multi-gigabyte buffer, a loop that never ends or a wait of a century.
//! The bounds are wide: each sits one or more orders of magnitude beyond
//! what a motor test on a lab rig needs, so no real configuration meets
//! them. They are listed for users in `docs/connect-your-rig.md`
//! ("Bounds").
//!
//! The check functions return a [`BoundsError`] whose text is the reason;
//! the caller names the key and the file.

/// Highest sampling rate of the rig or of one channel, Hz: faster than any
/// bus here (Modbus, CAN, a serial stream) can carry a channel.
pub const MAX_SAMPLE_RATE_HZ: f64 = 100_000.0;

/// Lowest sampling rate of the rig or of one channel, Hz: slower, a
/// channel could not feed the settle detection or the stale-reading check.
pub const MIN_SAMPLE_RATE_HZ: f64 = 0.1;

/// Longest single wait of a test plan, s (a settle window, a level's
/// timeout, a hold, a coast-down, a cool-down).
pub const MAX_WAIT_S: f64 = 3_600.0;

/// Longest a whole test may take when every step runs to its timeout, s.
pub const MAX_TEST_DURATION_S: f64 = 86_400.0;

/// Most readings per channel a whole test may take when every step runs
/// to its timeout. The record file grows with it, and `replay` and
/// `identify` read a record file into memory whole (the live test's
/// memory does not grow with its length: `record::thinning`).
pub const MAX_TEST_READINGS: f64 = 5e7;

/// Most samples in one settle window, or averaged into one operating
/// point: the settle detector keeps two windows per channel.
pub const MAX_WINDOW_SAMPLES: usize = 1_000_000;

/// Most voltage levels of a DC staircase, or voltages of an
/// induction-machine sweep.
pub const MAX_LEVELS: usize = 1_000;

/// Most slip points per induction-machine sweep.
pub const MAX_SWEEP_POINTS: usize = 1_000;

/// Longest deadline of one bus call, ms.
pub const MAX_CALL_TIMEOUT_MS: u64 = 10_000;

/// Most extra attempts of one bus call.
pub const MAX_RETRIES: u32 = 10;

/// Most failed polls in a row before a test ends.
pub const MAX_LOST_POLLS: u32 = 1_000;

/// Longest supervision timeout (a stale channel, a lost bus), s: a
/// supervisor that notices a lost bus later than this does not supervise.
pub const MAX_SUPERVISION_TIMEOUT_S: f64 = 10.0;

/// Shortest time step between two rows of an imported CSV file, s.
pub const MIN_CSV_STEP_S: f64 = 1e-6;

/// Longest time step between two rows of an imported CSV file, s.
pub const MAX_CSV_STEP_S: f64 = 10.0;

/// Largest magnitude of a time in an imported CSV file, s: a Unix time in
/// seconds fits (until the year 2286); beyond it a step of a microsecond
/// is below the resolution of a double.
pub const MAX_CSV_TIME_S: f64 = 1e10;

/// Why a number is refused by one of the checks below. Its text is the
/// reason alone: the caller names the key and the file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum BoundsError {
    /// Not a finite number above zero (at or above zero with `zero_ok`).
    #[error("{value} must be a finite number {} 0", lowest(*.zero_ok))]
    NotPositive {
        /// The number refused.
        value: f64,
        /// Whether zero was allowed.
        zero_ok: bool,
    },
    /// A sampling rate outside [`MIN_SAMPLE_RATE_HZ`] to
    /// [`MAX_SAMPLE_RATE_HZ`].
    #[error(
        "{value} Hz is outside {min} to {max} Hz (the practical range of a rig's channels)",
        min = MIN_SAMPLE_RATE_HZ,
        max = MAX_SAMPLE_RATE_HZ
    )]
    SampleRate {
        /// The rate refused, Hz.
        value: f64,
    },
    /// A wait longer than [`MAX_WAIT_S`].
    #[error("{value} s is beyond {max} s, the longest wait of one step", max = MAX_WAIT_S)]
    Wait {
        /// The wait refused, s.
        value: f64,
    },
    /// A window of more than [`MAX_WINDOW_SAMPLES`] samples (or not a
    /// number of samples at all).
    #[error(
        "{samples} samples is beyond {max}, the most one window holds",
        max = MAX_WINDOW_SAMPLES
    )]
    Window {
        /// The number of samples refused.
        samples: f64,
    },
    /// A list with more entries than it may have.
    #[error("{count} entries: at most {max}")]
    Entries {
        /// The number of entries.
        count: usize,
        /// The most allowed.
        max: usize,
    },
    /// A test that could take longer than [`MAX_TEST_DURATION_S`].
    #[error(
        "the test could take {duration_s:.0} s with every step at its timeout: at most {max} s",
        max = MAX_TEST_DURATION_S
    )]
    TestDuration {
        /// The longest the test could take, s.
        duration_s: f64,
    },
    /// A test that could take more than [`MAX_TEST_READINGS`] readings
    /// per channel.
    #[error(
        "the test could take {readings:.3e} readings per channel ({duration_s:.0} s at {rate_hz} Hz): at most {max:.0e}, what a record file read back whole may hold",
        max = MAX_TEST_READINGS
    )]
    TestReadings {
        /// The readings per channel the test could take.
        readings: f64,
        /// The longest the test could take, s.
        duration_s: f64,
        /// The rate it is read at, Hz.
        rate_hz: f64,
    },
    /// A bus call's deadline of zero or beyond [`MAX_CALL_TIMEOUT_MS`].
    #[error("{ms} ms: want 1 to {max}", max = MAX_CALL_TIMEOUT_MS)]
    CallTimeout {
        /// The deadline refused, ms.
        ms: u64,
    },
    /// A count (retries, lost polls) above its most.
    #[error("{value}: at most {max}")]
    AboveMost {
        /// The count refused.
        value: u32,
        /// The most allowed.
        max: u32,
    },
    /// A supervision timeout beyond [`MAX_SUPERVISION_TIMEOUT_S`].
    #[error(
        "{value} s is beyond {max} s: a fault would go unnoticed that long",
        max = MAX_SUPERVISION_TIMEOUT_S
    )]
    SupervisionTimeout {
        /// The timeout refused, s.
        value: f64,
    },
}

/// The lowest a number may be, as a comparison: `≥` with `zero_ok`, else `>`.
fn lowest(zero_ok: bool) -> &'static str {
    if zero_ok {
        "≥"
    } else {
        ">"
    }
}

/// `v` as a sampling rate, Hz.
pub fn sample_rate(v: f64) -> Result<f64, BoundsError> {
    if !v.is_finite() || v <= 0.0 {
        return Err(BoundsError::NotPositive {
            value: v,
            zero_ok: false,
        });
    }
    if !(MIN_SAMPLE_RATE_HZ..=MAX_SAMPLE_RATE_HZ).contains(&v) {
        return Err(BoundsError::SampleRate { value: v });
    }
    Ok(v)
}

/// `v` as one wait of a plan, s: finite, > 0 (≥ 0 with `zero_ok`) and at
/// most [`MAX_WAIT_S`].
pub fn wait_s(v: f64, zero_ok: bool) -> Result<f64, BoundsError> {
    let low_ok = if zero_ok { v >= 0.0 } else { v > 0.0 };
    if !v.is_finite() || !low_ok {
        return Err(BoundsError::NotPositive { value: v, zero_ok });
    }
    if v > MAX_WAIT_S {
        return Err(BoundsError::Wait { value: v });
    }
    Ok(v)
}

/// `n` samples of a settle window or an average.
pub fn window_samples(n: f64) -> Result<usize, BoundsError> {
    if !(0.0..=MAX_WINDOW_SAMPLES as f64).contains(&n) {
        return Err(BoundsError::Window { samples: n });
    }
    Ok(n as usize)
}

/// `n` entries of a list that has at most `max`.
pub fn count(n: usize, max: usize) -> Result<usize, BoundsError> {
    if n > max {
        return Err(BoundsError::Entries { count: n, max });
    }
    Ok(n)
}

/// The longest a test takes, `duration_s`, read at `rate_hz`: within
/// [`MAX_TEST_DURATION_S`] and [`MAX_TEST_READINGS`].
pub fn test_length(duration_s: f64, rate_hz: f64) -> Result<(), BoundsError> {
    if !(duration_s.is_finite() && duration_s <= MAX_TEST_DURATION_S) {
        return Err(BoundsError::TestDuration { duration_s });
    }
    let readings = duration_s * rate_hz;
    if readings > MAX_TEST_READINGS {
        return Err(BoundsError::TestReadings {
            readings,
            duration_s,
            rate_hz,
        });
    }
    Ok(())
}

/// A bus call's deadline, ms: > 0 and at most [`MAX_CALL_TIMEOUT_MS`].
pub fn call_timeout_ms(ms: u64) -> Result<u64, BoundsError> {
    if ms == 0 || ms > MAX_CALL_TIMEOUT_MS {
        return Err(BoundsError::CallTimeout { ms });
    }
    Ok(ms)
}

/// `n` at most `max` (retries, lost polls).
pub fn at_most(n: u32, max: u32) -> Result<u32, BoundsError> {
    if n > max {
        return Err(BoundsError::AboveMost { value: n, max });
    }
    Ok(n)
}

/// A supervision timeout, s: finite, > 0, at most
/// [`MAX_SUPERVISION_TIMEOUT_S`].
pub fn supervision_timeout_s(v: f64) -> Result<f64, BoundsError> {
    if !(v.is_finite() && v > 0.0) {
        return Err(BoundsError::NotPositive {
            value: v,
            zero_ok: false,
        });
    }
    if v > MAX_SUPERVISION_TIMEOUT_S {
        return Err(BoundsError::SupervisionTimeout { value: v });
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_waits_and_windows_are_bounded_both_ways() {
        assert_eq!(sample_rate(2000.0), Ok(2000.0));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e12, 0.01] {
            assert!(sample_rate(bad).is_err(), "{bad}");
        }
        assert_eq!(wait_s(10.0, false), Ok(10.0));
        assert_eq!(wait_s(0.0, true), Ok(0.0));
        for bad in [0.0, 1e7, f64::NAN, -1.0] {
            assert!(wait_s(bad, false).is_err(), "{bad}");
        }
        assert_eq!(window_samples(200.0), Ok(200));
        assert!(window_samples(1e10)
            .unwrap_err()
            .to_string()
            .contains("1000000"));
        assert!(window_samples(f64::NAN).is_err());
        assert!(count(1001, MAX_LEVELS).is_err() && count(3, MAX_LEVELS).is_ok());
    }

    #[test]
    fn a_test_is_bounded_in_time_and_in_readings() {
        assert!(test_length(80.0, 2000.0).is_ok());
        let e = test_length(1e5, 1.0).unwrap_err().to_string();
        assert!(e.contains("86400"), "{e}");
        let e = test_length(3600.0, 100_000.0).unwrap_err().to_string();
        assert!(e.contains("readings per channel"), "{e}");
        assert!(test_length(f64::NAN, 1.0).is_err());
    }

    #[test]
    fn bus_and_supervision_numbers_are_bounded() {
        assert_eq!(call_timeout_ms(200), Ok(200));
        assert!(call_timeout_ms(0).is_err() && call_timeout_ms(1 << 40).is_err());
        assert!(at_most(11, MAX_RETRIES).is_err() && at_most(2, MAX_RETRIES).is_ok());
        assert_eq!(supervision_timeout_s(0.25), Ok(0.25));
        for bad in [0.0, 60.0, f64::INFINITY] {
            assert!(supervision_timeout_s(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn messages_are_the_reason_alone_and_the_case_is_matchable() {
        let cases = [
            (wait_s(-1.0, true).unwrap_err(), "-1 must be a finite number ≥ 0"),
            (sample_rate(0.0).unwrap_err(), "0 must be a finite number > 0"),
            (
                sample_rate(1e6).unwrap_err(),
                "1000000 Hz is outside 0.1 to 100000 Hz (the practical range of a rig's channels)",
            ),
            (
                wait_s(4000.0, false).unwrap_err(),
                "4000 s is beyond 3600 s, the longest wait of one step",
            ),
            (
                test_length(3600.0, 100_000.0).unwrap_err(),
                "the test could take 3.600e8 readings per channel (3600 s at 100000 Hz): at most 5e7, what a record file read back whole may hold",
            ),
            (call_timeout_ms(0).unwrap_err(), "0 ms: want 1 to 10000"),
            (
                supervision_timeout_s(60.0).unwrap_err(),
                "60 s is beyond 10 s: a fault would go unnoticed that long",
            ),
        ];
        for (error, message) in cases {
            assert_eq!(error.to_string(), message);
        }
        // A sign error and a range error are told apart without the text.
        assert!(matches!(
            wait_s(-1.0, false),
            Err(BoundsError::NotPositive { zero_ok: false, .. })
        ));
        assert!(matches!(wait_s(1e7, false), Err(BoundsError::Wait { .. })));
    }
}
