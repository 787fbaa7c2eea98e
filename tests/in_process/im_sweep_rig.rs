//! The `im_slip_sweep` test on the simulated rig (VFD, dynamometer,
//! sensors with noise), recorded to MCAP, read back and identified; and
//! the limits that stop it.

use motorbench::bench::{NoProgress, Outcome, RecordSink};
use motorbench::identify::identify_im;
use motorbench::machine::im::{
    run_im_sweep, sim_im_rig, sweep_channels, ImSweepPlan, SimImRigConfig,
};
use motorbench::model::{
    with_leakage_split, Connection, ImCircuit, ImModel, ImParam, ImSupply, LeakageSplit,
    PerUnitBase, RotorCage, SEED_DOUBLE_CAGE_PU,
};
use motorbench::record::{read_mcap, EventLevel, Recorder, SegmentKind, TestMeta, SCHEMA_VERSION};
use motorbench_drivers::{PowerStage, SensorStream};

/// The seed paper's double cage as a 4 kW, 400 V star machine.
fn machine() -> (ImCircuit, ImSupply, f64) {
    let rated_current = 8.3;
    let base = PerUnitBase::from_rating(400.0, rated_current, Connection::Star);
    // Rs ×4 and Rr2 ×2, to look like a small industrial motor.
    let seed = SEED_DOUBLE_CAGE_PU;
    let RotorCage::Double { rr1, rr2, xr1, xr2 } = seed.rotor else {
        unreachable!("the seed machine has a double cage")
    };
    let pu = ImCircuit {
        rs: seed.rs * 4.0,
        rotor: RotorCage::Double {
            rr1,
            rr2: rr2 * 2.0,
            xr1,
            xr2,
        },
        ..seed
    };
    let supply = ImSupply {
        line_voltage: 400.0,
        frequency: 50.0,
        connection: Connection::Star,
        pole_pairs: 2,
    };
    (ImCircuit::from_per_unit(&pu, &base), supply, rated_current)
}

fn meta() -> TestMeta {
    TestMeta {
        schema_version: SCHEMA_VERSION.into(),
        kind: SegmentKind::ImSlipSweep,
        motor_id: "sim-double-cage".into(),
        started_at: "2026-11-21T12:00:00Z".into(),
        nameplate: serde_json::json!({"power_W": 4000.0, "voltage_V": 400.0, "current_A": 8.3,
            "speed_rpm": 1440.0, "poles": 4, "frequency_Hz": 50.0, "connection": "star"}),
        config: String::new(),
    }
}

#[tokio::test]
async fn sweep_records_operating_points_that_identify_the_machine() {
    let (circuit, supply, rated) = machine();
    let mut cfg = SimImRigConfig::new(circuit, supply);
    cfg.thermal_resistance_k_per_w = 0.0;
    cfg.encoder_lines = 4096;
    let (mut vfd, mut dyno, mut sensors) = sim_im_rig(cfg).unwrap();
    let mut plan = ImSweepPlan::new(400.0, rated, 50.0, 2);
    plan.encoder_counts_per_rev = 4.0 * 4096.0;
    plan.cooldown_s = 2.0;
    let channels = sweep_channels(sensors.channels(), vfd.id(), dyno.id());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sweep.mcap");
    let recorder = Recorder::start(&path, &meta(), &channels, 1024).unwrap();
    let mut sink = RecordSink::new(Some(recorder), Some(meta()), channels);
    let (_stop_tx, stop) = tokio::sync::watch::channel(false);
    let outcome = run_im_sweep(
        &plan,
        &plan.safety_rules(),
        &mut vfd,
        &mut dyno,
        &mut sensors,
        &mut sink,
        &NoProgress,
        &stop,
    )
    .await
    .unwrap();
    assert_eq!(outcome, Outcome::Completed);
    let (recorder, live) = sink.into_parts();
    recorder.unwrap().finish().await.unwrap();

    let record = read_mcap(&path).unwrap();
    assert_eq!(
        record.operating_points, live.operating_points,
        "replay sees what the bench saw"
    );
    let n = record.operating_points.len();
    assert!(n >= 2 * 28, "{n} operating points of 60");
    assert!(record
        .events
        .iter()
        .any(|(_, e)| e.message.contains("cool-down")));
    // Slip is measured (encoder), not the set point, and spans the sweep.
    let slips: Vec<f64> = record.operating_points.iter().map(|p| p.slip).collect();
    assert!(
        slips.iter().cloned().fold(1.0, f64::min) < 0.01
            && slips.iter().cloned().fold(0.0, f64::max) > 0.95
    );

    let id = identify_im(&record, None, ImModel::Double);
    let lm = &id.report.methods["lm"];
    assert!(lm.applies, "{:?}", id.report);
    let fit = id.lm.as_ref().unwrap();
    println!(
        "{n} points; lm rms {:.3} % (I), {:.3} % (P); held-out NRMSE {:?}",
        100.0 * fit.current_rms_relative,
        100.0 * fit.power_rms_relative.unwrap(),
        lm.validation_nrmse
    );
    assert!(lm.validation_nrmse.unwrap() < 0.01);
    let conventional = with_leakage_split(&circuit, LeakageSplit::default()).unwrap();
    let mut outside = Vec::new();
    for &p in ImModel::Double.params() {
        let f = fit.param(p).unwrap();
        let t = conventional.get(p).unwrap();
        println!(
            "  {p:4} {:.4} (conventional truth {t:.4}) ci95 {:?}",
            f.value, f.ci95
        );
        if !f.ci95.is_some_and(|[lo, hi]| lo <= t && t <= hi) {
            outside.push(p);
        }
        // Whatever the interval says, the estimate is within 1 % of the
        // conventional circuit.
        assert!((f.value / t - 1.0).abs() < 0.01, "{p}: {} vs {t}", f.value);
    }
    // The intervals assume the slip exact; the rig measures it with an
    // encoder on a shaft that is settled only to the detector's tolerance,
    // so a cage element may miss its (0.1 %-wide) interval by a hair.
    assert!(outside.len() <= 2, "outside their interval: {outside:?}");
    assert!(!outside.contains(&ImParam::Rs) && !outside.contains(&ImParam::Xs));
}

#[tokio::test]
async fn over_current_stops_the_sweep_with_both_stages_safe() {
    let (circuit, supply, rated) = machine();
    let (mut vfd, mut dyno, mut sensors) =
        sim_im_rig(SimImRigConfig::new(circuit, supply)).unwrap();
    let mut plan = ImSweepPlan::new(400.0, rated, 50.0, 2);
    plan.max_current = 3.0 * rated;
    let channels = sweep_channels(sensors.channels(), vfd.id(), dyno.id());
    let mut sink = RecordSink::new(None, None, channels);
    let (_stop_tx, stop) = tokio::sync::watch::channel(false);
    let outcome = run_im_sweep(
        &plan,
        &plan.safety_rules(),
        &mut vfd,
        &mut dyno,
        &mut sensors,
        &mut sink,
        &NoProgress,
        &stop,
    )
    .await
    .unwrap();
    let Outcome::Aborted { reason } = outcome else {
        panic!("not aborted")
    };
    assert!(reason.contains("limit tripped: current"), "{reason}");
    let (_, record) = sink.into_parts();
    assert!(record
        .events
        .iter()
        .any(|(_, e)| e.level == EventLevel::Abort));
    // After the stop the supply is off: the current decays to nothing.
    let mut last = f64::NAN;
    for _ in 0..200 {
        let b = sensors.next_batch().await.unwrap();
        last = b.samples[1].value;
    }
    assert!(last.abs() < 1e-6, "current {last} A after the safe state");
}

#[tokio::test]
async fn heating_budget_stops_a_sweep_without_cool_down() {
    let (circuit, supply, rated) = machine();
    let (mut vfd, mut dyno, mut sensors) =
        sim_im_rig(SimImRigConfig::new(circuit, supply)).unwrap();
    let mut plan = ImSweepPlan::new(400.0, rated, 50.0, 2);
    plan.cooldown_s = 0.0;
    plan.hot_point_max_s = 30.0;
    plan.max_i2t_s = 20.0;
    plan.slips = vec![1.0; 10];
    let channels = sweep_channels(sensors.channels(), vfd.id(), dyno.id());
    let mut sink = RecordSink::new(None, None, channels);
    let (_stop_tx, stop) = tokio::sync::watch::channel(false);
    let outcome = run_im_sweep(
        &plan,
        &plan.safety_rules(),
        &mut vfd,
        &mut dyno,
        &mut sensors,
        &mut sink,
        &NoProgress,
        &stop,
    )
    .await
    .unwrap();
    let Outcome::Aborted { reason } = outcome else {
        panic!("not aborted")
    };
    assert!(reason.contains("heating budget"), "{reason}");
}

#[tokio::test]
async fn operator_stop_ends_the_sweep() {
    let (circuit, supply, rated) = machine();
    let (mut vfd, mut dyno, mut sensors) =
        sim_im_rig(SimImRigConfig::new(circuit, supply)).unwrap();
    let plan = ImSweepPlan::new(400.0, rated, 50.0, 2);
    let channels = sweep_channels(sensors.channels(), vfd.id(), dyno.id());
    let mut sink = RecordSink::new(None, None, channels);
    let (_stop_tx, stop) = tokio::sync::watch::channel(true);
    let outcome = run_im_sweep(
        &plan,
        &plan.safety_rules(),
        &mut vfd,
        &mut dyno,
        &mut sensors,
        &mut sink,
        &NoProgress,
        &stop,
    )
    .await
    .unwrap();
    assert_eq!(
        outcome,
        Outcome::Aborted {
            reason: "operator stop".into()
        }
    );
}
