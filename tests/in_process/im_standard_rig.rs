//! The standard test set (`im_standard_tests`) on the simulated rig in
//! process, through the [`Machine`] trait: the readings the plan records
//! round-trip through MCAP; an operator stop in the middle of the no-load
//! test ends it as aborted with every stage (supply, dynamometer, DC
//! source) safe, and the record keeps the finished DC test; a winding
//! read by a thermometer as it warms has the DC resistance corrected to
//! the locked-rotor test's temperature, and the locked-rotor test run
//! again at reduced frequency reduces to the machine.

use crate::common::dry_run;
use motorbench::bench::{NoProgress, Outcome, Progress, RecordSink};
use motorbench::identify::identify_im;
use motorbench::machine::im::{sim_im_rig, ImRunConfig, COPPER_ALPHA, NO_LOAD_SEGMENT};
use motorbench::machine::{Machine, PlanRig};
use motorbench::record::{
    read_mcap, DcResistanceReading, Entry, EventLevel, Recorder, SegmentKind, StandardTestReading,
    SupplyReading, TestMeta, SCHEMA_VERSION,
};
use motorbench_drivers::{PowerStage, SensorStream};
use tokio::sync::watch;

const SIM_IM_STANDARD: &str = include_str!("../../config/sim-im-standard.toml");

fn meta() -> TestMeta {
    TestMeta {
        schema_version: SCHEMA_VERSION.into(),
        kind: SegmentKind::ImSlipSweep,
        motor_id: "sim".into(),
        started_at: "2026-12-03T12:00:00Z".into(),
        nameplate: serde_json::json!({"voltage_V": 400.0, "connection": "star"}),
        config: String::new(),
    }
}

#[tokio::test]
async fn standard_test_readings_round_trip_and_a_non_finite_one_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("std.mcap");
    let dc = DcResistanceReading {
        segment: 0,
        dc_voltage: 3.4,
        dc_current: 2.0,
        winding_temperature: Some(21.5),
    };
    let supply = |segment, line_voltage| SupplyReading {
        segment,
        line_voltage,
        line_current: 2.0,
        input_power: 150.0,
        frequency: 50.0,
        winding_temperature: None,
    };
    let readings = [
        StandardTestReading::ImDcResistance(dc),
        StandardTestReading::ImNoLoad(supply(1, 400.0)),
        StandardTestReading::ImLockedRotor(supply(2, 60.0)),
    ];
    let rec = Recorder::start(&path, &meta(), &[], 8).unwrap();
    for (k, reading) in readings.into_iter().enumerate() {
        rec.send(Entry::StandardTest {
            t_ns: k as u64,
            reading,
        })
        .await
        .unwrap();
    }
    let mut bad = supply(1, 380.0);
    bad.frequency = f64::NAN;
    let e = rec
        .send(Entry::StandardTest {
            t_ns: 9,
            reading: StandardTestReading::ImNoLoad(bad),
        })
        .await
        .unwrap_err();
    assert!(e.to_string().contains("frequency"), "{e}");
    let stats = rec.finish().await.unwrap();
    assert_eq!(stats.per_topic["/bench/standard_test"], 3);
    let tests = read_mcap(&path).unwrap().standard_tests;
    assert_eq!(tests.dc_resistance, [dc]);
    assert_eq!(tests.no_load, [supply(1, 400.0)]);
    assert_eq!(tests.locked_rotor, [supply(2, 60.0)]);
}

/// A record whose winding temperature is in kelvin (another tool's, or a
/// rig's thermometer mapped wrongly) is refused on reading, naming the
/// topic and the key: the fits scale Rs by it.
#[tokio::test]
async fn a_winding_temperature_in_kelvin_is_refused_on_reading() {
    let dir = tempfile::tempdir().unwrap();
    let kelvin = SupplyReading {
        segment: 1,
        line_voltage: 400.0,
        line_current: 2.0,
        input_power: 150.0,
        frequency: 50.0,
        winding_temperature: Some(294.65),
    };
    let path = dir.path().join("kelvin.mcap");
    record_one_no_load_reading(&path, kelvin).await;
    let e = read_mcap(&path).unwrap_err().to_string();
    assert!(
        e.contains("/bench/standard_test")
            && e.contains("winding_temperature 294.65")
            && e.contains("not K"),
        "{e}"
    );
    // The same reading in °C reads.
    let path = dir.path().join("celsius.mcap");
    let celsius = SupplyReading {
        winding_temperature: Some(21.5),
        ..kelvin
    };
    record_one_no_load_reading(&path, celsius).await;
    assert_eq!(read_mcap(&path).unwrap().standard_tests.no_load, [celsius]);
}

/// A record at `path` holding one no-load reading.
async fn record_one_no_load_reading(path: &std::path::Path, reading: SupplyReading) {
    let rec = Recorder::start(path, &meta(), &[], 8).unwrap();
    rec.send(Entry::StandardTest {
        t_ns: 1,
        reading: StandardTestReading::ImNoLoad(reading),
    })
    .await
    .unwrap();
    rec.finish().await.unwrap();
}

/// Raises the operator's stop when segment `at` begins.
struct StopAt {
    at: usize,
    stop: watch::Sender<bool>,
}

impl Progress for StopAt {
    fn segment(&self, index: usize, _: usize, _: &str) {
        if index == self.at {
            self.stop.send_replace(true);
        }
    }
    fn tick(&self, _: f64) {}
    fn done(&self, _: &str) {}
}

#[tokio::test]
async fn a_stop_during_the_no_load_test_leaves_every_stage_safe() {
    let cfg = ImRunConfig::parse("sim-im-standard.toml", SIM_IM_STANDARD).unwrap();
    let (vfd, dyno, mut sensors) = sim_im_rig(cfg.simulated.clone().unwrap()).unwrap();
    let dc = vfd
        .dc_source()
        .expect("the standard plan's rig has a DC source");
    let mut stages: Vec<Box<dyn PowerStage>> = vec![
        Box::new(vfd.clone()),
        Box::new(dyno.clone()),
        Box::new(dc.clone()),
    ];
    let ids: Vec<String> = stages.iter().map(|s| s.id().to_string()).collect();
    let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
    let channels = cfg.record_channels(sensors.channels(), &ids);
    let mut sink = RecordSink::new(None, Some(meta()), channels);
    let (tx, rx) = watch::channel(false);
    let progress = StopAt {
        at: NO_LOAD_SEGMENT,
        stop: tx,
    };
    let rig = PlanRig {
        stages: &mut stages,
        sensors: &mut sensors,
        counts_per_rev: cfg.plan.encoder_counts_per_rev,
    };
    let outcome = cfg.run_plan(rig, &mut sink, &progress, (&rx).into()).await;
    match outcome.unwrap() {
        Outcome::Aborted { reason } => assert!(reason.contains("operator stop"), "{reason}"),
        other => panic!("not aborted: {other:?}"),
    }
    assert!(!vfd.output_enabled(), "supply off");
    assert_eq!(dyno.command(), (0.0, true), "dynamometer braking to rest");
    // The DC source is disconnected: it may connect again only because
    // the supply is off and it is in its safe state (no current).
    let mut probe = dc.clone();
    probe.set_output_enabled(true).await.unwrap();
    probe.safe_state().await.unwrap();

    let (_, record) = sink.into_parts();
    assert_eq!(record.standard_tests.dc_resistance.len(), 3);
    assert!(record.standard_tests.no_load.is_empty());
    let labels: Vec<&str> = record.segments.iter().map(|s| s.label.as_str()).collect();
    assert!(labels[1].ends_with("(incomplete)"), "{labels:?}");
    assert!(record
        .events
        .iter()
        .any(|(_, e)| e.level == EventLevel::Abort));
}

#[tokio::test]
async fn the_plan_with_the_nameplate_defaults_runs_to_its_end() {
    // The standard tests with the nameplate's defaults (the shipped
    // file's tables left out), then a short load test (two voltages of
    // five slips): every segment completes, in order.
    let tables = SIM_IM_STANDARD.find("[test.dc_resistance]").unwrap();
    let text = SIM_IM_STANDARD[..tables].replace("points = 30", "points = 5");
    assert!(!text.contains("[test.no_load]"));
    let cfg = ImRunConfig::parse("sim-im-standard.toml", &text).unwrap();
    let mut rig = cfg.open_rig(false).await.unwrap();
    let ids: Vec<String> = rig
        .stages
        .iter()
        .map(|s| s.stage.id().to_string())
        .collect();
    let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
    let channels = cfg.record_channels(rig.sensors.channels(), &ids);
    let mut sink = RecordSink::new(None, Some(meta()), channels);
    let (_tx, rx) = watch::channel(false);
    let mut stages: Vec<Box<dyn PowerStage>> = rig.stages.drain(..).map(|s| s.stage).collect();
    assert_eq!(stages.len(), 3);
    let plan_rig = PlanRig {
        stages: &mut stages,
        sensors: rig.sensors.as_mut(),
        counts_per_rev: rig.counts_per_rev,
    };
    let outcome = cfg
        .run_plan(plan_rig, &mut sink, &NoProgress, (&rx).into())
        .await
        .unwrap();
    assert_eq!(outcome, Outcome::Completed);
    let (_, record) = sink.into_parts();
    let kinds: Vec<SegmentKind> = record.segments.iter().map(|s| s.kind.unwrap()).collect();
    assert_eq!(
        kinds,
        [
            SegmentKind::ImDcResistance,
            SegmentKind::ImNoLoad,
            SegmentKind::ImLockedRotor,
            SegmentKind::ImSlipSweep,
            SegmentKind::ImSlipSweep
        ]
    );
    assert!(record
        .segments
        .iter()
        .all(|s| !s.label.contains("incomplete")));
    assert_eq!(record.standard_tests.no_load.len(), 10);
    assert_eq!(record.operating_points.len(), 10);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_warming_winding_is_corrected_to_its_measured_temperature_and_a_reduced_frequency_test_reduces(
) {
    // The shipped machine with a winding thermometer, a winding that heats
    // forty times faster (0.2 K/W, 20 s) and the locked-rotor test again
    // at 12.5 Hz with the nameplate's default voltages.
    let text = SIM_IM_STANDARD
        .replace(
            "torque_sensor = true",
            "torque_sensor = true\nwinding_sensor = true",
        )
        .replace("resistance_K_per_W = 0.005", "resistance_K_per_W = 0.2")
        .replace("time_constant_s = 300", "time_constant_s = 20")
        .replace(
            "max_current_A = 9.5 ",
            "reduced_frequency_Hz = 12.5\nmax_current_A = 9.5 ",
        );
    let cfg = ImRunConfig::parse("sim-im-standard.toml", &text).unwrap();
    assert!(cfg.standard.as_ref().unwrap().reduced_frequency.is_some());
    let (_dir, done) = dry_run::commission(&cfg).await;
    assert_eq!(done.outcome, Outcome::Completed);
    let tests = &done.record.standard_tests;
    let mean = |rs: &[&SupplyReading]| {
        rs.iter()
            .map(|r| r.winding_temperature.unwrap())
            .sum::<f64>()
            / rs.len() as f64
    };
    let reduced: Vec<&SupplyReading> = tests
        .locked_rotor
        .iter()
        .filter(|r| r.segment == 3)
        .collect();
    assert!(reduced.len() >= 3 && reduced.iter().all(|r| r.frequency == 12.5));
    let t_dc = tests.dc_resistance[0].winding_temperature.unwrap();
    let t_lr = mean(&reduced);
    // The no-load and locked-rotor tests warmed the winding well above
    // the DC reading's temperature.
    assert!(
        t_lr > t_dc + 3.0,
        "DC at {t_dc} °C, locked rotor at {t_lr} °C"
    );

    let report = serde_json::to_value(done.analysis.report()).unwrap();
    let param = |r: &serde_json::Value, key: &str| {
        r["methods"]["standard_tests"]["params"][key]["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("no {key}: {r}"))
    };
    // Rs at the locked-rotor test's temperature, Rr the machine's.
    let rs_hot = 0.8659 * (1.0 + COPPER_ALPHA * (t_lr - 20.0));
    let rs = param(&report, "Rs");
    assert!((rs / rs_hot - 1.0).abs() < 0.005, "Rs {rs}, truth {rs_hot}");
    let rr = param(&report, "Rr");
    assert!((rr / 1.2 - 1.0).abs() < 0.02, "Rr {rr}");
    for key in ["Xs", "Xr", "Xm"] {
        let truth = match key {
            "Xs" => 1.84,
            "Xr" => 2.76,
            _ => 119.64,
        };
        let got = param(&report, key);
        assert!(
            (got / truth - 1.0).abs() < 0.02,
            "{key} {got}, truth {truth}"
        );
    }

    // The load test runs last and hottest; its points carry the
    // thermometer's reading too, so the joint fit sees Rs at each point's
    // temperature and reports it at the locked-rotor test's (0.24 % off;
    // 5.6 % high, and Rr 0.7 %, when the points carried none).
    let joint = |key: &str| {
        report["methods"]["joint"]["params"][key]["value"]
            .as_f64()
            .unwrap_or_else(|| panic!("no joint {key}: {report}"))
    };
    let points = &done.record.operating_points;
    assert!(!points.is_empty());
    let t_load = points
        .iter()
        .map(|p| p.winding_temperature.expect("a load point's temperature"))
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(t_load > t_lr + 5.0, "load test up to {t_load} °C");
    for (key, truth, tol) in [
        ("Rs", rs_hot, 0.01),
        ("Rr", 1.2, 0.01),
        ("Xm", 119.64, 0.01),
    ] {
        let got = joint(key);
        println!("joint {key} {got:.5} (truth {truth:.5})");
        assert!(
            (got / truth - 1.0).abs() < tol,
            "joint {key} {got}, truth {truth}"
        );
    }
    // The rest of the joint fit, for the figures docs/identification-im.md
    // quotes.
    println!("joint Rfe {:.1}, Pfw {:.2} W", joint("Rfe"), joint("Pfw"));

    // The same readings without their temperatures: the warm winding's
    // extra copper resistance lands in Rr.
    let mut cold = done.record.clone();
    let st = &mut cold.standard_tests;
    st.dc_resistance
        .iter_mut()
        .for_each(|r| r.winding_temperature = None);
    st.no_load
        .iter_mut()
        .for_each(|r| r.winding_temperature = None);
    st.locked_rotor
        .iter_mut()
        .for_each(|r| r.winding_temperature = None);
    let uncorrected = identify_im(&cold, None, cfg.model);
    let uncorrected = serde_json::to_value(&uncorrected.report).unwrap();
    let rr_cold = param(&uncorrected, "Rr");
    println!(
        "DC at {t_dc:.2} °C, locked rotor (12.5 Hz) at {t_lr:.2} °C: Rs {rs:.5} (truth {rs_hot:.5}), \
         Rr {rr:.5} (truth 1.2), uncorrected Rs {:.5}, Rr {rr_cold:.5}",
        param(&uncorrected, "Rs")
    );
    assert!(
        rr_cold - 1.2 > 0.5 * (rs_hot - 0.8659),
        "uncorrected Rr {rr_cold}, corrected {rr}"
    );
}
