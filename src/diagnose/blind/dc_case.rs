//! A blind DC case (to be built).

use rand::rngs::StdRng;

use super::BlindRecord;
use crate::model::Effect;

/// Simulate one DC staircase record with `effect` withheld (None: no effect).
pub fn simulate_dc_case(_effect: Option<Effect>, _rng: &mut StdRng) -> BlindRecord {
    unimplemented!("DC blind case")
}
