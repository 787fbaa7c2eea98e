//! The induction-machine row of the peer comparison: the double-cage
//! Levenberg–Marquardt fit (current and power, relative residuals,
//! whitened, l = 7) of three slip sweeps of 50 points at 100, 80 and 60 %
//! of rated voltage, from the classical starts; the leakage split is left
//! as fitted (`SplitPolicy::Never`) so that both sides solve the same
//! least-squares problem. The data are those of `benches/identify_im.rs`.

use std::path::Path;

use motorbench::identify::{
    classical_starts, fit_lm, slip_grid, LmOptions, PhaseData, SlipSweep, SplitPolicy, SweepNoise,
};
use motorbench::model::{
    Connection, ImCircuit, ImModel, ImSupply, LeakageSplit, PerUnitBase, SEED_DOUBLE_CAGE_PU,
};
use rand::rngs::StdRng;
use rand::SeedableRng;
use serde_json::json;

/// Three sweeps of the seed paper's double cage on a 4 kW, 400 V star base.
fn data() -> PhaseData {
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
    sweep.expect("three segments").phase_data()
}

fn values(c: &ImCircuit) -> Vec<f64> {
    ImModel::Double
        .params()
        .iter()
        .map(|p| c.get(*p).expect("a double-cage element"))
        .collect()
}

/// Time `fit_lm` alone; write the points and the starts for the peer.
pub fn run(problem: &Path) -> serde_json::Value {
    let d = data();
    let mut opts = LmOptions::new(ImModel::Double);
    opts.split_policy = SplitPolicy::Never;
    let (fit, seconds) = super::best_of(|| fit_lm(&d, &opts).expect("the fit"));
    let starts = classical_starts(&d, ImModel::Double, LeakageSplit::default(), None)
        .expect("classical starts");
    let names: Vec<String> = ImModel::Double
        .params()
        .iter()
        .map(|p| format!("{p:?}"))
        .collect();
    let doc = json!({
        "params": names,
        "slip": d.slip, "voltage": d.voltage, "current": d.current, "power": d.power,
        "starts": starts.iter().map(values).collect::<Vec<_>>(),
        "screen_bound": motorbench::identify::evaluation_bound(d.len(), 7) / starts.len(),
        "bound": motorbench::identify::evaluation_bound(d.len(), 7),
    });
    std::fs::write(problem, doc.to_string()).expect("the problem file is written");
    json!({"seconds": seconds, "params": values(&fit.circuit), "names": names,
           "starts": fit.starts.0, "evaluations": fit.evaluations, "points": d.len()})
}
