//! The induction-machine row of the peer comparison: the double-cage
//! Levenberg–Marquardt fit (current and power, relative residuals,
//! whitened, l = 7) of three slip sweeps of 50 points at 100, 80 and 60 %
//! of rated voltage, from the classical starts; the leakage split is left
//! as fitted (`SplitPolicy::Never`) so that both sides solve the same
//! least-squares problem. The data are those of `benches/identify_im.rs`.
//! The answer compared is the fitted current and power at every point:
//! the double cage's circuit is determined only up to a one-parameter
//! family (the reason for the leakage-split convention).

use std::path::Path;

use motorbench::identify::{classical_starts, fit_lm, predict, LmOptions, SplitPolicy};
use motorbench::model::{ImCircuit, ImModel, LeakageSplit};
use serde_json::json;

#[path = "../common/im_sweeps.rs"]
mod im_sweeps;

fn values(c: &ImCircuit) -> Vec<f64> {
    ImModel::Double
        .params()
        .iter()
        .map(|p| c.get(*p).expect("a double-cage element"))
        .collect()
}

/// Time `fit_lm` alone; write the points and the starts for the peer.
pub fn run(problem: &Path) -> serde_json::Value {
    let (d, _) = im_sweeps::double_cage_sweeps();
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
    // The double cage's seven elements are one more than terminal readings
    // determine (a one-parameter family of circuits gives the same
    // impedance at every slip), so the answer compared is what the fit
    // determines: the predicted current and power at every point.
    let prediction: Vec<f64> = {
        let (i, p): (Vec<f64>, Vec<f64>) = (0..d.len())
            .map(|k| predict(&fit.circuit, d.slip[k], d.voltage[k]))
            .unzip();
        i.into_iter().chain(p).collect()
    };
    json!({"seconds": seconds, "params": values(&fit.circuit), "names": names,
           "prediction": prediction,
           "starts": fit.starts.0, "evaluations": fit.evaluations, "points": d.len()})
}
