//! The readings of the induction machine's standard tests from an
//! equivalent circuit: the DC resistance between two line terminals, the
//! no-load test with a friction-and-windage load on the shaft (the rotor
//! runs at the slip where the air-gap power covers it), and the
//! locked-rotor test at any frequency. Test fixtures for the classical
//! reduction; and [`free_rotor_slip`], where the simulated rig's uncoupled
//! rotor runs with friction and windage on its shaft.

use super::im::{Connection, ImCircuit, ImSupply, RotorCage, C64};

/// One simulated reading on an AC supply, terminal values (line voltage
/// and current RMS, three-phase power).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StandardReading {
    /// RMS line-to-line voltage, V.
    pub line_voltage: f64,
    /// RMS line current, A.
    pub line_current: f64,
    /// Three-phase input power, W.
    pub input_power: f64,
    /// Slip the rotor ran at.
    pub slip: f64,
}

/// Bisection steps for the no-load slip.
const SLIP_STEPS: usize = 200;

/// The circuit's reactances at `ratio` times the frequency they are given at.
pub fn at_frequency(c: &ImCircuit, ratio: f64) -> ImCircuit {
    let rotor = match c.rotor {
        RotorCage::Single { rr, xr } => RotorCage::Single { rr, xr: xr * ratio },
        RotorCage::Double { rr1, rr2, xr1, xr2 } => RotorCage::Double {
            rr1,
            rr2,
            xr1: xr1 * ratio,
            xr2: xr2 * ratio,
        },
    };
    ImCircuit {
        xs: c.xs * ratio,
        xm: c.xm * ratio,
        rotor,
        ..*c
    }
}

/// The DC resistance between two line terminals of a winding of `rs` per
/// phase: star `2·Rs`, delta `2/3·Rs`.
pub fn terminal_resistance(rs: f64, connection: Connection) -> f64 {
    match connection {
        Connection::Star => 2.0 * rs,
        Connection::Delta => 2.0 / 3.0 * rs,
    }
}

/// The terminal reading of `c` at slip `s` on `line_voltage`, and the
/// mechanical power `3·|Ir|²·Rr(s)·(1 − s)/s` it delivers, W.
fn at_slip(
    c: &ImCircuit,
    connection: Connection,
    line_voltage: f64,
    s: f64,
) -> (StandardReading, f64) {
    let v = connection.phase_voltage(line_voltage);
    let i = C64::new(v, 0.0) / c.impedance(s);
    let e = C64::new(v, 0.0) - i * C64::new(c.rs, c.xs);
    let ir = e * c.rotor_admittance(s);
    // The rotor's air-gap power less its copper loss.
    let p_gap = 3.0 * (e * ir.conj()).re;
    let reading = StandardReading {
        line_voltage,
        line_current: connection.line_current(i.norm()),
        input_power: 3.0 * (C64::new(v, 0.0) * i.conj()).re,
        slip: s,
    };
    (reading, p_gap * (1.0 - s))
}

/// The no-load reading of `c` (at its own frequency) on `line_voltage`
/// with `friction_windage` W on the shaft; `None` when no slip up to 0.5
/// delivers it (a voltage too low to turn the rotor).
pub fn no_load_reading(
    c: &ImCircuit,
    connection: Connection,
    line_voltage: f64,
    friction_windage: f64,
) -> Option<StandardReading> {
    let (mut lo, mut hi) = (0.0, 0.5);
    if at_slip(c, connection, line_voltage, hi).1 < friction_windage {
        return None;
    }
    for _ in 0..SLIP_STEPS {
        let mid = 0.5 * (lo + hi);
        if at_slip(c, connection, line_voltage, mid).1 < friction_windage {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some(at_slip(c, connection, line_voltage, hi).0)
}

/// Slip steps of the scan for the free rotor's operating point.
const SCAN_STEPS: usize = 1000;

/// The slip at which `c`, uncoupled on `supply`, runs with friction and
/// windage that take `friction_windage` W at synchronous speed (the loss
/// `∝ ω²`: a torque `∝ ω`): the smallest slip where the electromagnetic
/// torque `P_ag/ω_s` meets the friction torque (the stable branch below
/// breakdown), found by a scan and bisection. 0 without friction or
/// without voltage; close to 1 where the machine cannot turn its shaft
/// against them (the friction torque vanishes at standstill).
pub fn free_rotor_slip(c: &ImCircuit, supply: &ImSupply, friction_windage: f64) -> f64 {
    if !(friction_windage > 0.0 && supply.line_voltage > 0.0) {
        return 0.0;
    }
    let ws = std::f64::consts::TAU * supply.frequency / f64::from(supply.pole_pairs.max(1));
    // Electromagnetic less friction torque at slip `s`.
    let net = |s: f64| {
        let friction = friction_windage / ws * (1.0 - s);
        c.operating_point(supply, s).torque - friction
    };
    let step = 1.0 / SCAN_STEPS as f64;
    let Some(k) = (1..=SCAN_STEPS).find(|&k| net(k as f64 * step) >= 0.0) else {
        return 1.0;
    };
    let (mut lo, mut hi) = ((k - 1) as f64 * step, k as f64 * step);
    for _ in 0..SLIP_STEPS {
        let mid = 0.5 * (lo + hi);
        if net(mid) < 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// The locked-rotor reading of `c` (reactances at `rated_frequency`) on
/// `line_voltage` at `frequency`.
pub fn locked_rotor_reading(
    c: &ImCircuit,
    connection: Connection,
    line_voltage: f64,
    frequency: f64,
    rated_frequency: f64,
) -> StandardReading {
    at_slip(
        &at_frequency(c, frequency / rated_frequency),
        connection,
        line_voltage,
        1.0,
    )
    .0
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::model::im_fixtures::{single_cage, supply};

    #[test]
    fn the_no_load_rotor_delivers_its_friction_and_the_locked_one_nothing() {
        let c = single_cage(1.5, 3.0, 90.0, Some(1500.0), 1.6, 3.0);
        let r = no_load_reading(&c, Connection::Delta, 400.0, 60.0).unwrap();
        assert!(r.slip > 0.0 && r.slip < 0.01, "{r:?}");
        let (_, pm) = at_slip(&c, Connection::Delta, 400.0, r.slip);
        assert!((pm - 60.0).abs() < 1e-6);
        let lr = locked_rotor_reading(&c, Connection::Delta, 100.0, 50.0, 50.0);
        let z = c.impedance(1.0);
        let i = 100.0 / z.norm();
        assert!((lr.line_current - 3f64.sqrt() * i).abs() < 1e-9);
        assert!((lr.input_power - 3.0 * i * i * z.re).abs() < 1e-6);
        assert_eq!(terminal_resistance(1.5, Connection::Delta), 1.0);
    }

    #[test]
    fn the_free_rotor_turns_where_its_torque_meets_the_friction() {
        let c = single_cage(1.5, 3.0, 90.0, Some(1500.0), 1.6, 3.0);
        let supply = supply(400.0, 50.0, Connection::Delta, 2);
        let ws = std::f64::consts::PI * 50.0;
        let s = free_rotor_slip(&c, &supply, 60.0);
        assert!(s > 0.0 && s < 0.01, "{s}");
        // The shaft's friction torque at that speed, ∝ ω.
        let friction = 60.0 / ws * (1.0 - s);
        assert!((c.operating_point(&supply, s).torque - friction).abs() < 1e-9);
        assert_eq!(free_rotor_slip(&c, &supply, 0.0), 0.0);
        // Far more friction than the machine can turn: it (nearly) stalls.
        assert!(free_rotor_slip(&c, &supply, 1e7) > 0.99);
    }
}
