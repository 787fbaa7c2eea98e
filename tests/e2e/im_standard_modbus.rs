//! `motorbench run --config config/sim-modbus-im-standard.toml`: the
//! induction machine's standard test set over Modbus TCP on loopback —
//! the supply and dynamometer VFDs, the meter, the encoder counter with
//! the winding thermometer and the DC source (a Riden RD6006 map in
//! constant current) each a served simulated device sharing one plant,
//! reached through the real driver code on the wall clock. The plan runs
//! a DC winding-resistance reading, a no-load sweep (the dynamometer
//! coasts), a locked-rotor test at 50 Hz and again at 12.5 Hz (the
//! supply's frequency commanded over Modbus), then the load test. The
//! classical reduction (Rs corrected to the locked-rotor test's measured
//! winding temperature), the joint fit and the load test's fit meet the
//! simulated machine within stated tolerances; the record holds the five
//! segments, the temperatures (the load test's points' too) and the
//! frequency command; the Python reader
//! accepts it and `replay --check` reproduces the report exactly.

use super::im_standard_run::{read_back_and_replayed, standard_record, value, TRUTH};
use crate::common::replay::run_json;
use motorbench::machine::im::COPPER_ALPHA;

fn truth(key: &str) -> f64 {
    TRUTH.iter().find(|(k, _)| *k == key).unwrap().1
}

#[test]
fn the_standard_tests_run_over_modbus_with_a_reduced_frequency_locked_rotor_test() {
    let dir = tempfile::tempdir().unwrap();
    let v = run_json("sim-modbus-im-standard.toml", dir.path(), &["--quiet"]);
    // The record: the four kinds, the locked-rotor test twice.
    let (mcap, record) = standard_record(dir.path(), &["im_locked_rotor"]);
    let tests = &record.standard_tests;
    let at = |segment: u32| -> Vec<_> {
        let lr = tests.locked_rotor.iter();
        lr.filter(|r| r.segment == segment).collect()
    };
    let (rated, reduced) = (at(2), at(3));
    assert!(rated.len() >= 3 && reduced.len() >= 3, "{tests:?}");
    assert!(rated.iter().all(|r| r.frequency == 50.0));
    assert!(reduced.iter().all(|r| r.frequency == 12.5));
    // The reduced-frequency test reaches the current ceiling at a lower
    // voltage: the leakage reactance fell with the frequency.
    let volts_at_ceiling = |rs: &[&motorbench::record::SupplyReading]| {
        rs.iter()
            .find(|r| r.line_current > 9.5)
            .map(|r| r.line_voltage)
            .unwrap()
    };
    assert!(volts_at_ceiling(&reduced) < 0.7 * volts_at_ceiling(&rated));
    // Every reading carries the winding thermometer's temperature, near
    // the 20 °C ambient (the winding warms little in these tests).
    let temperatures: Vec<f64> = tests
        .dc_resistance
        .iter()
        .map(|r| r.winding_temperature)
        .chain(tests.no_load.iter().map(|r| r.winding_temperature))
        .chain(tests.locked_rotor.iter().map(|r| r.winding_temperature))
        .map(|t| t.expect("every reading has a temperature"))
        .collect();
    assert!(
        temperatures.iter().all(|t| (19.9..25.0).contains(t)),
        "{temperatures:?}"
    );
    // So does every point of the load test, whose winding is warmer.
    let load: Vec<f64> = record
        .operating_points
        .iter()
        .map(|p| {
            p.winding_temperature
                .expect("every point has a temperature")
        })
        .collect();
    assert!(!load.is_empty());
    assert!(
        load.iter().all(|t| (19.9..60.0).contains(t)) && load.last() > temperatures.last(),
        "{load:?} after {temperatures:?}"
    );

    // The classical reduction, from the 12.5 Hz locked-rotor test (its
    // reactances scaled to 50 Hz). Rs is the DC reading corrected to the
    // locked-rotor test's mean temperature: the truth at that temperature
    // to 0.3 % (150 averaged readings of a Riden's 10 mV and 1 mA
    // registers at 0.5 % noise). The other tolerances are
    // tests/e2e/im_standard_run.rs's.
    let method = &v["methods"]["standard_tests"];
    assert_eq!(method["applies"], true, "{method}");
    let t_lr = reduced
        .iter()
        .map(|r| r.winding_temperature.unwrap())
        .sum::<f64>()
        / reduced.len() as f64;
    let rs_hot = truth("Rs") * (1.0 + COPPER_ALPHA * (t_lr - 20.0));
    let rs = value(&v, "standard_tests", "Rs");
    assert!(
        (rs / rs_hot - 1.0).abs() < 0.003,
        "Rs {rs}, truth {rs_hot} at {t_lr} °C"
    );
    let warnings = v["warnings"].to_string();
    assert!(
        warnings.contains("corrected to the locked-rotor test's"),
        "{warnings}"
    );
    let tolerance = |key: &str| match key {
        "Xm" => 0.01,
        "Pfw" => 0.03,
        _ => 0.02,
    };
    for (key, t) in TRUTH.iter().filter(|(k, _)| *k != "Rs") {
        let got = value(&v, "standard_tests", key);
        assert!(
            (got / t - 1.0).abs() < tolerance(key),
            "standard_tests {key} = {got}, truth {t}"
        );
        let ci = &method["params"][key]["ci95"];
        assert!(ci.is_array(), "standard_tests {key} has an interval: {ci}");
    }
    // The 50 Hz test's rotor beside it: the simulated single cage has no
    // deep bar, so the same to 2 %.
    for key in ["Rr", "Xr"] {
        let got = value(&v, "standard_tests", &format!("{key}_rated_frequency"));
        assert!(
            (got / truth(key) - 1.0).abs() < 0.02,
            "{key}_rated_frequency = {got}"
        );
    }
    assert!(warnings.contains("12.5 Hz and 50 Hz"), "{warnings}");

    // The joint fit of every reading (both locked-rotor tests at their
    // frequencies), the best: every element to 1 %, Pfw to 3 %, and to
    // 2 % Rfe, the least determined element (the core loss is a few per
    // cent of the input power; seen 1.1 % off when a loaded machine
    // shifted the polled samples, its 95 % interval then [1586, 1598]),
    // and Rr, which the load test's points pull with the slip of a polled
    // encoder (seen from −0.3 % to +1.2 % over CI runs). The joint fit's
    // Rs is the winding at the locked-rotor test's temperature (the DC
    // reading corrected to it bounds it; src/machine/im/identify/joint.rs),
    // so it is held to the truth at that temperature, as the reduction's
    // is: against the 20 °C value it came out 1.5 % high once, the winding
    // a few kelvin warm on a run the wall clock made longer. The load test
    // comes last, while the simulated winding warms under load (0.393 %/K,
    // a 300 s time constant); its points carry the thermometer's reading,
    // so each sees Rs scaled to its own temperature and the warming no
    // longer pulls Rs up. Rs to 2 % all the same: the joint fit determines
    // it to about ±0.8 % (its 95 % interval; the load points' slip comes
    // from a polled encoder), and runs gave +0.21 % and +0.80 %.
    assert_eq!(v["best"], "joint", "{}", v["best"]);
    for (key, t) in TRUTH {
        let t = if key == "Rs" { rs_hot } else { t };
        let got = value(&v, "joint", key);
        let tol = match key {
            "Pfw" => 0.03,
            "Rfe" | "Rr" | "Rs" => 0.02,
            _ => 0.01,
        };
        assert!(
            (got / t - 1.0).abs() < tol,
            "joint {key} = {got}, truth {t}"
        );
    }

    // The load test's fit (one sweep of 16 points behind a polled
    // encoder): Rs, Xm and Rr to 5 %, the leakage sum to 5 %. Its Rfe is
    // not checked: from one voltage's sweep it rests on the few points
    // near synchronous speed, where the polled encoder's timing moves the
    // slip most (it came out 12 % high, and in clean CI runs at its bound,
    // not determined; the standard tests pin it). Rs trades against it:
    // seen 2.8 % high with Rfe at its bound.
    for key in ["Rs", "Xm", "Rr"] {
        let got = value(&v, "lm", key);
        assert!(
            (got / truth(key) - 1.0).abs() < 0.05,
            "lm {key} = {got}, truth {}",
            truth(key)
        );
    }
    let leakage = value(&v, "lm", "Xs") + value(&v, "lm", "Xr");
    assert!((leakage / 4.6 - 1.0).abs() < 0.05, "lm Xs + Xr = {leakage}");

    // The Python reader accepts the record: the readings, the thermometer,
    // the DC source's read-back and the frequency command; the replay
    // reduces the recorded readings to the same report.
    let topics = ["/sensor/winding_temperature", "/command/supply_frequency"];
    read_back_and_replayed(&mcap, &record, &v, &topics);
}
