//! Circuits and supplies the induction-machine tests share: the
//! single-cage circuit by its six values and the supplies the tests feed
//! it from, so that a test names only the values that matter to it.

use super::{Connection, ImCircuit, ImSupply, RotorCage};

/// A single-cage circuit: stator `rs`, `xs`; magnetising `xm`; iron loss
/// `rfe`; rotor `rr`, `xr` (Ω).
pub(crate) fn single_cage(
    rs: f64,
    xs: f64,
    xm: f64,
    rfe: Option<f64>,
    rr: f64,
    xr: f64,
) -> ImCircuit {
    ImCircuit {
        rs,
        xs,
        xm,
        rfe,
        rotor: RotorCage::Single { rr, xr },
    }
}

/// A supply of `line_voltage` V at `frequency` Hz to a machine of
/// `pole_pairs`, wound as `connection`.
pub(crate) fn supply(
    line_voltage: f64,
    frequency: f64,
    connection: Connection,
    pole_pairs: u32,
) -> ImSupply {
    ImSupply {
        line_voltage,
        frequency,
        connection,
        pole_pairs,
    }
}

/// The tests' usual supply: 400 V, 50 Hz, a four-pole machine in star.
pub(crate) const STAR_400V_50HZ: ImSupply = ImSupply {
    line_voltage: 400.0,
    frequency: 50.0,
    connection: Connection::Star,
    pole_pairs: 2,
};
