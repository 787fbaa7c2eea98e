//! The induction-machine data the IM fit benches time (`identify_im` and
//! the peer comparison's `im_fit` row): three slip sweeps of 50 points of
//! the seed paper's double cage at 100 %, 80 % and 60 % of rated voltage,
//! 0.5 % relative noise, a fixed seed.

use motorbench::identify::{slip_grid, PhaseData, SlipSweep, SweepNoise};
use motorbench::model::{Connection, ImCircuit, ImSupply, PerUnitBase, SEED_DOUBLE_CAGE_PU};
use rand::rngs::StdRng;
use rand::SeedableRng;

/// The sweeps (as phase data) and the circuit they were simulated with,
/// on a 4 kW, 400 V star base.
pub fn double_cage_sweeps() -> (PhaseData, ImCircuit) {
    let circuit = ImCircuit::from_per_unit(
        &SEED_DOUBLE_CAGE_PU,
        &PerUnitBase::from_rating(400.0, 8.3, Connection::Star),
    );
    let mut rng = StdRng::seed_from_u64(1);
    let mut sweep: Option<SlipSweep> = None;
    for (segment, v) in [400.0, 320.0, 240.0].into_iter().enumerate() {
        let supply = ImSupply {
            line_voltage: v,
            frequency: 50.0,
            connection: Connection::Star,
            pole_pairs: 2,
        };
        let s = SlipSweep::simulate(
            &circuit,
            &supply,
            &slip_grid(50, 0.002),
            &SweepNoise::relative(0.005),
            segment as u32,
            &mut rng,
        );
        match &mut sweep {
            Some(all) => all.extend(s),
            None => sweep = Some(s),
        }
    }
    (sweep.expect("three segments").phase_data(), circuit)
}
