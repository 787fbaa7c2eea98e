//! A blind IM case (to be built).

use rand::rngs::StdRng;

use super::BlindRecord;
use crate::model::Effect;

/// Simulate one IM slip-sweep record with `effect` withheld (None: no effect).
pub fn simulate_im_case(_effect: Option<Effect>, _rng: &mut StdRng) -> BlindRecord {
    unimplemented!("IM blind case")
}
