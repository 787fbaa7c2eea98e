//! Bad input through the CLI: a one-line error naming the file (and line
//! and field where there is one), exit code 2, never a panic.

use crate::common;
use crate::mcap_corpus;

use std::path::Path;

use motorbench::record::{read_mcap, RecordError};

fn run_bad(args: &[&str]) -> String {
    let out = common::motorbench(args);
    let (_, stderr) = common::text(&out);
    assert_eq!(
        out.status.code(),
        Some(2),
        "exit code for {args:?}; stderr: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(stderr.trim_end().lines().count(), 1, "one line: {stderr}");
    stderr
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn config_with_an_unknown_key_names_file_line_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let text =
        motorbench::config::DEFAULT_CONFIG.replace("[limits]", "[limits]\nmax_torque_Nm = 3");
    let path = write(dir.path(), "rig.toml", &text);
    let err = run_bad(&[
        "run",
        "--config",
        &path,
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    let line = text
        .lines()
        .position(|l| l.starts_with("max_torque_Nm"))
        .unwrap()
        + 1;
    assert!(err.contains(&format!("rig.toml:{line}:")), "{err}");
    assert!(err.contains("max_torque_Nm"), "{err}");
}

#[test]
fn config_with_an_invalid_value_names_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let text =
        motorbench::config::DEFAULT_CONFIG.replace("sample_rate_Hz = 2000", "sample_rate_Hz = -5");
    let path = write(dir.path(), "rig.toml", &text);
    let err = run_bad(&[
        "run",
        "--config",
        &path,
        "--out",
        dir.path().to_str().unwrap(),
    ]);
    assert!(
        err.contains("rig.toml") && err.contains("rig.sample_rate_Hz"),
        "{err}"
    );
}

#[test]
fn missing_config_file_is_named() {
    let err = run_bad(&["run", "--config", "no/such/rig.toml"]);
    assert!(err.contains("no/such/rig.toml"), "{err}");
}

#[test]
fn csv_with_a_non_number_names_file_line_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let csv =
        "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,60,0.11,42\n0.001,60,abc,42\n";
    let path = write(dir.path(), "step.csv", csv);
    let err = run_bad(&["identify", "--kind", "dc_step", &path]);
    assert!(
        err.contains("step.csv:3") && err.contains("armature_current_A"),
        "{err}"
    );
}

#[test]
fn csv_with_a_missing_column_or_time_going_back_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "a.csv",
        "time_s,armature_voltage_V,speed_rad_s\n0,60,42\n",
    );
    let err = run_bad(&["identify", "--kind", "dc_step", &path]);
    assert!(
        err.contains("a.csv") && err.contains("armature_current_A"),
        "{err}"
    );
    let csv =
        "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,60,0.1,42\n0,60,0.1,42\n";
    let path = write(dir.path(), "b.csv", csv);
    let err = run_bad(&["identify", "--kind", "dc_step", &path]);
    assert!(err.contains("b.csv:3") && err.contains("time_s"), "{err}");
}

#[test]
fn garbage_and_empty_mcap_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "junk.mcap", "this is not an MCAP file at all");
    let err = run_bad(&["replay", &path]);
    assert!(err.contains("junk.mcap"), "{err}");
    let path = write(dir.path(), "empty.mcap", "");
    let err = run_bad(&["identify", "--kind", "dc_step", &path]);
    assert!(err.contains("empty.mcap"), "{err}");
}

#[test]
fn nameplate_that_is_not_json_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let csv = write(
        dir.path(),
        "s.csv",
        "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,1,1,1\n",
    );
    let np = write(dir.path(), "np.json", "{\n  \"power_W\": 180,\n  oops\n}\n");
    let err = run_bad(&["identify", "--kind", "dc_step", "--nameplate", &np, &csv]);
    assert!(err.contains("np.json:3"), "{err}");
}

#[test]
fn usage_errors_exit_2() {
    let out = common::motorbench(&["identify", "--kind", "dc_step"]);
    assert_eq!(out.status.code(), Some(2));
    let out = common::motorbench(&["frobnicate"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn a_truncated_record_replays_what_it_holds_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let out = common::motorbench(&[
        "run",
        "--out",
        dir.path().to_str().unwrap(),
        "--quiet",
        "--json",
        "--no-diagnose",
    ]);
    assert!(out.status.success());
    let mcap = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .unwrap();
    let bytes = std::fs::read(&mcap).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 6 / 10]).unwrap();
    let out = common::motorbench(&["replay", "--no-diagnose", cut.to_str().unwrap()]);
    let (stdout, stderr) = common::text(&out);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(
        stderr.contains("damaged") && stderr.contains("recovered"),
        "{stderr}"
    );
    // About 60 % of the staircase survives: enough levels to identify.
    assert_eq!(out.status.code(), Some(0), "{stderr}");
    assert!(stdout.contains("method steady_state"), "{stdout}");
}

/// The line of the first line of `text` starting with `prefix`, 1-based.
fn line_of(text: &str, prefix: &str) -> usize {
    text.lines().position(|l| l.starts_with(prefix)).unwrap() + 1
}

#[test]
fn config_numbers_that_size_memory_loops_or_waits_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().to_str().unwrap();
    // Each once aborted the process allocating hundreds of gigabytes.
    let dc = motorbench::config::DEFAULT_CONFIG;
    for (from, to, key) in [
        (
            "sample_rate_Hz = 2000",
            "sample_rate_Hz = 1e12",
            "rig.sample_rate_Hz",
        ),
        ("window_s = 0.1", "window_s = 1e7", "test.settle.window_s"),
        // Each level's wait within bounds, but 8 levels of 3 500 s at
        // 2 kHz are 5.6·10⁷ readings per channel.
        (
            "timeout_s = 10",
            "timeout_s = 3500",
            "test.settle.timeout_s",
        ),
    ] {
        assert!(dc.contains(from), "{from}");
        let text = dc.replacen(from, to, 1);
        let path = write(dir.path(), "rig.toml", &text);
        let err = run_bad(&["run", "--config", &path, "--out", out]);
        let line = line_of(&text, to);
        assert!(
            err.contains(&format!("rig.toml:{line}: {key}:")),
            "{to}: {err}"
        );
    }
    let im = include_str!("../../config/sim-im.toml");
    let from = "average_samples = 50";
    assert!(im.contains(from));
    let text = im.replacen(from, "average_samples = 100000000000", 1);
    let path = write(dir.path(), "im.toml", &text);
    let err = run_bad(&["run", "--config", &path, "--out", out]);
    let line = line_of(&text, "average_samples");
    assert!(
        err.contains(&format!("im.toml:{line}: test.settle.average_samples:")),
        "{err}"
    );
}

/// A DC step segment at 1 kHz, `rows` rows, with row `k`'s time from `t`.
fn dc_csv(rows: usize, t: impl Fn(usize) -> String) -> String {
    let mut s = String::from("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n");
    for k in 0..rows {
        let i = 1.9 * (-(k as f64) / 30.0).exp() + 0.1;
        let w = 40.0 * (1.0 - (-(k as f64) / 200.0).exp());
        s += &format!("{},60,{i:.5},{w:.4}\n", t(k));
    }
    s
}

#[test]
fn csv_times_that_break_the_numerics_are_refused_at_import() {
    let dir = tempfile::tempdir().unwrap();
    let good = write(
        dir.path(),
        "a.csv",
        &dc_csv(400, |k| format!("{}", k as f64 * 1e-3)),
    );
    // Each made `identify` or `diagnose` panic ("Singular value was NaN").
    let cases = [
        (
            "tiny_step.csv",
            dc_csv(400, |k| format!("{:e}", k as f64 * 1e-300)),
            3,
        ),
        (
            "huge.csv",
            dc_csv(400, |k| format!("{:e}", 1e300 + k as f64 * 1e290)),
            2,
        ),
        (
            "one_huge.csv",
            dc_csv(400, |k| {
                if k == 399 {
                    "1e308".into()
                } else {
                    format!("{}", k as f64 * 1e-3)
                }
            }),
            401,
        ),
    ];
    for (name, text, line) in cases {
        let bad = write(dir.path(), name, &text);
        for command in ["identify", "diagnose"] {
            let err = run_bad(&[command, "--kind", "dc_step", &good, &bad]);
            assert!(
                err.contains(&format!("{name}:{line}: column time_s:")),
                "{command} {name}: {err}"
            );
        }
    }
}

/// An implausible reading in the third of four files without a
/// declaration is reported with that file's path and the reading's line
/// (a comment line before it counted).
#[test]
fn an_implausible_reading_names_the_file_and_line_that_hold_it() {
    let dir = tempfile::tempdir().unwrap();
    let files: Vec<String> = (0..4)
        .map(|n| {
            let mut text = dc_csv(400, |k| format!("{}", k as f64 * 1e-3));
            if n == 2 {
                text = text.replacen(",60,1.93771,", ",60,5e6,", 1).replacen(
                    "speed_rad_s\n",
                    "speed_rad_s\n# logger restarted\n",
                    1,
                );
            }
            write(dir.path(), &format!("part-{n}.csv"), &text)
        })
        .collect();
    let mut args = vec!["identify", "--kind", "dc_step"];
    args.extend(files.iter().map(String::as_str));
    let err = run_bad(&args);
    assert!(
        err.starts_with(&format!("motorbench: {}:4: segment 2", files[2]))
            && err.contains("column armature_current_A: sample 1 reads 5e6 A"),
        "{err}"
    );
}

#[test]
fn a_huge_bad_csv_field_is_cut_in_the_message() {
    let dir = tempfile::tempdir().unwrap();
    let field = "x".repeat(10 << 20);
    let csv = format!(
        "time_s,armature_voltage_V,armature_current_A,speed_rad_s\n0,60,0.11,42\n0.001,60,{field},42\n"
    );
    let path = write(dir.path(), "big.csv", &csv);
    let err = run_bad(&["identify", "--kind", "dc_step", &path]);
    assert!(
        err.contains("big.csv:3: column armature_current_A:"),
        "{}",
        &err[..err.len().min(300)]
    );
    assert!(err.len() < 300, "{} bytes: {}", err.len(), &err[..300]);
    assert!(err.contains(&format!("…({} bytes)", 10 << 20)), "{err}");
}

/// What reading a corrupted copy gave: the offset the reader names, and
/// the record when it recovered one.
fn read_corrupted(path: &Path) -> (u64, Option<motorbench::record::Record>) {
    let name = path.file_name().unwrap().to_str().unwrap();
    match read_mcap(path) {
        Ok(record) => {
            let r = record
                .recovery
                .clone()
                .unwrap_or_else(|| panic!("{name}: read as intact"));
            assert!(r.messages > 0, "{name}: {r:?}");
            assert!(
                r.reason.contains(&format!("byte {} of", r.offset)),
                "{name}: {r:?}"
            );
            (r.offset, Some(record))
        }
        Err(e) => {
            let text = e.to_string();
            let RecordError::Damaged { offset, .. } = e else {
                panic!("{name}: not refused as damaged: {text}");
            };
            assert!(
                text.contains(name) && text.contains(&format!("byte {offset} of")),
                "{name}: {text}"
            );
            assert_eq!(text.lines().count(), 1, "{text}");
            (offset, None)
        }
    }
}

#[test]
fn corrupted_mcap_corpus_is_recovered_up_to_the_damage_or_refused_with_its_offset() {
    let seed = mcap_corpus::seed();
    let dir = tempfile::tempdir().unwrap();
    let cases = mcap_corpus::write(mcap_corpus::corpus(&seed, 40, 15), dir.path());
    // Recovered records by how many messages they kept (many cases keep
    // the same prefix): one of each is identified.
    let mut recovered = std::collections::BTreeMap::new();
    let mut refused = 0;
    for (case, path) in &cases {
        let (offset, record) = read_corrupted(path);
        assert!(offset <= case.bytes.len() as u64, "{}", case.name);
        if let Some(at) = case.damaged_record {
            assert_eq!(offset, at, "{}: the damaged record", case.name);
        }
        if let Some(record) = record {
            let messages = record.recovery.as_ref().unwrap().messages;
            recovered.insert(messages, (case.name.clone(), record));
        } else {
            refused += 1;
        }
    }
    assert!(
        refused > 0 && recovered.len() > 1,
        "{refused} {:?}",
        recovered.keys()
    );
    for (name, record) in recovered.values() {
        // Identification of what was recovered runs and says the record
        // was damaged, and where.
        let id = motorbench::identify::identify_dc(record);
        assert!(
            id.report
                .warnings
                .iter()
                .any(|w| w.contains("damaged at byte")),
            "{name}: {:?}",
            id.report.warnings
        );
    }
}

#[test]
fn a_chunk_with_a_wrong_crc_is_reported_not_replayed_as_identical() {
    // A record made by this build (the checked-in seed's /bench/result is
    // from the build that made it, so its replay differs once the
    // identification changes), with the seed's configuration.
    let dir = tempfile::tempdir().unwrap();
    let made = dir.path().join("made");
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/mcap_corpus/seed.toml");
    let out = common::motorbench(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--out",
        made.to_str().unwrap(),
        "--quiet",
        "--no-diagnose",
    ]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    let file = std::fs::read_dir(&made)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("the run wrote a record");
    let seed = std::fs::read(&file).unwrap();
    let intact = dir.path().join("intact.mcap");
    std::fs::write(&intact, &seed).unwrap();
    let out = common::motorbench(&["replay", "--no-diagnose", intact.to_str().unwrap()]);
    let (_, stderr) = common::text(&out);
    assert!(stderr.contains("identical"), "the seed replays: {stderr}");

    let cases = mcap_corpus::forged(&seed)
        .into_iter()
        .filter(|c| c.name.starts_with("chunk-crc-") || c.name.starts_with("chunk-content-"));
    for (case, path) in mcap_corpus::write(cases.collect(), dir.path()) {
        let at = case.damaged_record.unwrap();
        let out = common::motorbench(&["replay", "--no-diagnose", path.to_str().unwrap()]);
        let (_, stderr) = common::text(&out);
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(
            stderr.contains("damaged") && stderr.contains(&format!("byte {at} of")),
            "{}: {stderr}",
            case.name
        );
        assert!(!stderr.contains("identical"), "{}: {stderr}", case.name);
        assert!(matches!(out.status.code(), Some(0 | 4)), "{stderr}");
    }
}

#[test]
fn huge_lengths_in_an_mcap_are_refused_or_recovered_by_every_command() {
    let seed = mcap_corpus::seed();
    let dir = tempfile::tempdir().unwrap();
    let cases = mcap_corpus::forged(&seed)
        .into_iter()
        .filter(|c| c.name.starts_with("message-len-") || c.name.starts_with("len-max-op06"));
    for (case, path) in mcap_corpus::write(cases.collect(), dir.path()) {
        let at = case.damaged_record.unwrap();
        let file = path.to_str().unwrap();
        for args in [
            &["replay", "--no-diagnose", file][..],
            &["identify", "--kind", "dc_step", file],
            &["diagnose", "--kind", "dc_step", file],
        ] {
            let out = common::motorbench(args);
            let (_, stderr) = common::text(&out);
            assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
            // Refused (2), or recovered and identified (0) or not (4).
            assert!(
                matches!(out.status.code(), Some(0 | 2 | 4)),
                "{args:?}: {:?} {stderr}",
                out.status
            );
            assert!(
                stderr.contains(&format!("byte {at} of")),
                "{args:?}: {stderr}"
            );
        }
    }
}

/// The lab's load curve (`tests/data/im_lab/load.csv`) with column `col`
/// of every reading mapped by `f`, written to `dir/load.csv`.
fn lab_load_with(dir: &Path, col: usize, f: impl Fn(f64) -> f64) -> String {
    let load = std::fs::read_to_string("tests/data/im_lab/load.csv").unwrap();
    let mut edited = String::new();
    for line in load.lines() {
        let mut cols: Vec<String> = line.split(',').map(String::from).collect();
        if let Some(Ok(v)) = cols.get(col).map(|c| c.parse::<f64>()) {
            cols[col] = format!("{}", f(v));
        }
        edited += &(cols.join(",") + "\n");
    }
    write(dir, "load.csv", &edited)
}

/// `identify` and `diagnose` both refuse `path` with an error holding
/// every one of `words`.
fn refused_by_both(path: &str, words: &[&str]) {
    for command in ["identify", "diagnose"] {
        let err = run_bad(&[command, "--kind", "im_slip_sweep", path]);
        assert!(words.iter().all(|w| err.contains(w)), "{command}: {err}");
    }
}

#[test]
fn a_reversed_wattmeter_is_refused_naming_the_file_and_column() {
    let dir = tempfile::tempdir().unwrap();
    let path = lab_load_with(dir.path(), 3, |p| -p);
    refused_by_both(
        &path,
        &["load.csv", "column input_power_W", "polarity reversed"],
    );
}

#[test]
fn a_phase_voltage_in_the_line_voltage_column_is_refused() {
    // The lab's load curve reads power factors up to 0.81; with the line
    // voltage divided by √3 they read up to 1.40.
    let dir = tempfile::tempdir().unwrap();
    let path = lab_load_with(dir.path(), 1, |v| v / 3f64.sqrt());
    refused_by_both(&path, &["load.csv", "power factor", "phase voltage"]);
}

#[test]
fn input_power_in_kilowatts_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = lab_load_with(dir.path(), 3, |p| p / 1000.0);
    refused_by_both(&path, &["load.csv", "column input_power_W", "in kW"]);
}

#[test]
fn a_reader_that_goes_away_ends_the_output_without_a_panic() {
    // `motorbench identify … | head -0`: the pipe is closed before the
    // report is written.
    let data = "tests/data/im_lab/load.csv";
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_motorbench"))
        .args(["identify", "--kind", "im_slip_sweep", "--json", data])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "{stderr}");
    assert!(
        out.status.code().is_some(),
        "killed by a signal: {:?}",
        out.status
    );
}
