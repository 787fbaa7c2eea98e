//! `config/sim-modbus-im.toml`: the induction-machine slip sweep on the
//! simulated rig served behind Modbus TCP (supply and dynamometer VFDs
//! with the Optidrive E3 map, an SDM630-map meter, an encoder counter),
//! reached through the real driver code, against the same configuration
//! run on the direct simulated rig. The identification of the two runs
//! must agree within noise.
//!
//! "Within noise" is measured, not assumed: the direct rig is run again
//! with other noise seeds, and each parameter's spread over those runs
//! (its standard deviation σ) sets the scale. A parameter agrees when the
//! difference is within 4σ, or within the two runs' combined 95 %
//! intervals where those are wider, or within 1 %: the Modbus run has a
//! noise the reseeded direct runs lack, the jitter of the polled encoder's
//! timestamps (tenths of a millisecond on a loaded machine, about 1e-4 of
//! slip per point after averaging, a few per cent at the lowest slip),
//! which moves the outer-cage resistance by a few tenths of a per cent. The differences are printed (run with
//! `--nocapture`).

use std::path::Path;

use crate::common::{dry_run, motorbench, probed, text};
use motorbench::bench::Outcome;
use motorbench::machine::im::ImRunConfig;

fn shipped() -> ImRunConfig {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sim-modbus-im.toml");
    ImRunConfig::load(&path).unwrap()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn modbus_sweep_identifies_the_machine_as_the_direct_rig_does() {
    let cfg = shipped();
    assert!(cfg.modbus.as_ref().is_some_and(|m| m.simulate.is_some()));
    let mut direct_cfg = cfg.clone();
    direct_cfg.modbus = None;
    let (_direct_dir, direct) = dry_run::commission(&direct_cfg).await;
    let (_modbus_dir, modbus) = dry_run::commission(&cfg).await;
    assert_eq!(direct.outcome, Outcome::Completed);
    assert_eq!(modbus.outcome, Outcome::Completed);

    let dp = &direct.record.operating_points;
    let mp = &modbus.record.operating_points;
    for (d, m) in dp.iter().zip(mp) {
        println!(
            "slip {:.4} / {:.4}  V {:.2} / {:.2}  I {:.3} / {:.3}  P {:.1} / {:.1}",
            d.slip,
            m.slip,
            d.line_voltage,
            m.line_voltage,
            d.line_current,
            m.line_current,
            d.input_power,
            m.input_power
        );
    }
    assert_eq!(dp.len(), mp.len(), "the same points settled");

    // The dynamometer reached the same slips (its set point goes out at
    // 0.1 Hz resolution; the speed is measured by the encoder either way).
    for (d, m) in dp.iter().zip(mp) {
        assert!(
            (d.slip - m.slip).abs() <= 1e-3 + 0.01 * d.slip,
            "slip {} direct, {} behind Modbus",
            d.slip,
            m.slip
        );
    }

    // The noise: the direct rig with other seeds.
    let params = |c: &motorbench::session::Commissioned| {
        let r = serde_json::to_value(c.analysis.report()).unwrap();
        let best = r["best"].as_str().unwrap().to_string();
        (best.clone(), r["methods"][&best]["params"].clone())
    };
    let mut reseeded: Vec<serde_json::Value> = Vec::new();
    for seed in 2..=9 {
        let mut c = direct_cfg.clone();
        c.simulated.as_mut().unwrap().seed = seed;
        let (_dir, run) = dry_run::commission(&c).await;
        reseeded.push(params(&run).1);
    }
    let sigma = |name: &str| {
        let v: Vec<f64> = reseeded
            .iter()
            .filter_map(|p| p[name]["value"].as_f64())
            .collect();
        assert!(v.len() >= 6, "{name} identified in most reseeded runs");
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
    };

    // Every identified parameter agrees within noise.
    let (db, d) = params(&direct);
    let (mb, m) = params(&modbus);
    assert_eq!(db, mb, "the same method is best");
    let d = d.as_object().unwrap();
    let m = m.as_object().unwrap();
    assert_eq!(
        d.keys().collect::<Vec<_>>(),
        m.keys().collect::<Vec<_>>(),
        "the same parameters are determined"
    );
    for (name, dv) in d {
        let mv = &m[name];
        let value = |v: &serde_json::Value| v["value"].as_f64().unwrap();
        let half = |v: &serde_json::Value| {
            let ci = v["ci95"].as_array().unwrap();
            (ci[1].as_f64().unwrap() - ci[0].as_f64().unwrap()) / 2.0
        };
        let diff = value(mv) - value(dv);
        let s = sigma(name);
        let allowed = (4.0 * s)
            .max(half(dv).hypot(half(mv)))
            .max(0.01 * value(dv).abs());
        println!(
            "{name}: direct {:.4}, Modbus {:.4} ohm: difference {:+.4} ({:+.2} %, {:.1} σ of the seed-to-seed spread {:.4}); allowed {:.4}",
            value(dv),
            value(mv),
            diff,
            100.0 * diff / value(dv),
            diff.abs() / s,
            s,
            allowed
        );
        assert!(
            diff.abs() <= allowed,
            "{name}: {} behind Modbus vs {} direct",
            value(mv),
            value(dv)
        );
    }
    // Both runs recorded every sample; the Modbus run's pollers left their
    // per-channel statistics in the record.
    let stats = modbus
        .record
        .events
        .iter()
        .filter(|(_, e)| e.message.starts_with("sampling statistics"))
        .count();
    assert_eq!(stats, 4, "line voltage, current, power, encoder count");
}

#[test]
fn probe_exercises_the_served_induction_machine_rig_through_modbus() {
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/config/sim-modbus-im.toml");
    let out = motorbench(&["probe", "--config", config, "--actuate"]);
    let (stdout, stderr) = text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("Modbus TCP"), "{stderr}");
    for q in [
        "line_voltage",
        "line_current",
        "input_power",
        "encoder_count",
    ] {
        let idle = probed(&stdout, "idle", q);
        assert!(idle[0].abs() < 1.0 || q == "encoder_count", "{q}: {idle:?}");
    }
    for cmd in [
        "[cmd ] supply: set point 22.000: ok",
        "[cmd ] supply: safe state: ok",
        "[cmd ] dynamometer: set point 9.425: ok",
        "[cmd ] dynamometer: safe state: ok",
    ] {
        assert!(stdout.contains(cmd), "{cmd}:\n{stdout}");
    }
    // The meter sees the supply's 22 V (0.5 % noise), then nothing once it
    // is safe again.
    let on = probed(&stdout, "on", "line_voltage");
    assert!((on[0] / 22.0 - 1.0).abs() < 0.05, "{on:?}\n{stdout}");
    let safe = probed(&stdout, "safe", "line_voltage");
    assert!(safe[0].abs() < 1.0, "{safe:?}\n{stdout}");
}
