//! Degenerate DC records through `motorbench identify` and `diagnose`
//! (issue 16, numerical robustness): a step too small, levels that never
//! settle, a saturated current or speed sensor, a constant signal, three
//! samples, a supply in current limit, a blocked rotor. Each gets either a
//! result with no NaN and every value in its physical range, or a one-line
//! reason with exit code 2 (bad input) or 4 (nothing to identify) — never
//! a panic, a NaN or a hang.

use std::fmt::Write;
use std::path::Path;

use crate::common;

/// The seed paper's motor (Table 4), simulated at 1 kHz by explicit Euler
/// steps (fine against La/Ra = 3 ms) from rest, with the voltage `u`,
/// the supply limiting the current to `limit`, with a deterministic dither
/// of a few ADC steps so the file is the same on every run.
fn simulate(u: &[f64], limit: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let (ra, la, k, j, f, tst) = (30.9, 0.1, 1.3186, 0.01, 5.06e-4, 0.1278);
    let dt = 1e-3;
    let (mut i, mut w) = (0.0f64, 0.0f64);
    let (mut us, mut is, mut ws) = (Vec::new(), Vec::new(), Vec::new());
    for (n, &v) in u.iter().enumerate() {
        let mut v = v;
        i += (v - ra * i - k * w) / la * dt;
        if i > limit {
            i = limit;
            v = ra * i + k * w;
        }
        let drive = k * i;
        let load = if w.abs() > 1e-9 {
            tst * w.signum()
        } else {
            drive.clamp(-tst, tst)
        };
        w += (drive - f * w - load) / j * dt;
        let d = ((n * 7919) % 17) as f64 / 17.0 - 0.5;
        us.push(v + 0.02 * d);
        is.push(i + 0.004 * d);
        ws.push(w + 0.1 * d);
    }
    (us, is, ws)
}

fn levels(levels: &[f64], hold_s: f64) -> Vec<f64> {
    let n = (hold_s * 1e3) as usize;
    levels
        .iter()
        .flat_map(|&v| std::iter::repeat_n(v, n))
        .collect()
}

fn write(dir: &Path, name: &str, u: &[f64], i: &[f64], w: &[f64]) -> String {
    let mut text = String::from("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n");
    for k in 0..u.len() {
        writeln!(text, "{},{},{},{}", k as f64 * 1e-3, u[k], i[k], w[k]).unwrap();
    }
    let path = dir.join(format!("{name}.csv"));
    std::fs::write(&path, text).unwrap();
    path.to_str().unwrap().to_string()
}

/// Every number in a JSON value.
fn numbers(v: &serde_json::Value, out: &mut Vec<f64>) {
    match v {
        serde_json::Value::Number(n) => out.push(n.as_f64().unwrap()),
        serde_json::Value::Array(a) => a.iter().for_each(|x| numbers(x, out)),
        serde_json::Value::Object(o) => o.values().for_each(|x| numbers(x, out)),
        _ => {}
    }
}

#[test]
fn degenerate_records_get_a_physical_answer_or_a_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let staircase = levels(&[0.0, 60.0, 248.0], 1.0);
    let mut cases: Vec<(&str, String, &[i32])> = Vec::new();

    let (u, i, w) = simulate(&levels(&[60.0, 60.3], 2.0), f64::INFINITY);
    cases.push(("a step too small", write(d, "small", &u, &i, &w), &[0]));
    let (u, i, w) = simulate(&levels(&[0.0, 60.0, 120.0, 248.0], 0.02), f64::INFINITY);
    cases.push(("levels held 20 ms", write(d, "unsettled", &u, &i, &w), &[0]));
    let (u, i, w) = simulate(&staircase, f64::INFINITY);
    let clipped: Vec<f64> = i.iter().map(|v| v.min(0.5)).collect();
    cases.push((
        "current clipped",
        write(d, "clip_i", &u, &clipped, &w),
        &[0],
    ));
    let clipped: Vec<f64> = w.iter().map(|v| v.min(50.0)).collect();
    cases.push(("speed clipped", write(d, "clip_w", &u, &i, &clipped), &[0]));
    let (u, i, w) = simulate(&levels(&[0.0, 248.0, 120.0], 1.5), 0.6);
    cases.push((
        "supply in current limit",
        write(d, "limit", &u, &i, &w),
        &[0],
    ));
    let flat = vec![60.0; 2000];
    cases.push((
        "a constant signal",
        write(d, "constant", &flat, &vec![0.1; 2000], &vec![40.0; 2000]),
        &[4],
    ));
    cases.push((
        "three samples",
        write(
            d,
            "three",
            &[0.0, 60.0, 60.0],
            &[0.0, 1.0, 0.5],
            &[0.0, 1.0, 2.0],
        ),
        &[4],
    ));
    let (u, i, _) = simulate(&staircase, f64::INFINITY);
    cases.push((
        "a blocked rotor",
        write(d, "blocked", &u, &i, &vec![0.0; u.len()]),
        &[4],
    ));

    for (what, file, codes) in &cases {
        for command in ["identify", "diagnose"] {
            let out = common::motorbench(&[command, "--kind", "dc_step", "--json", file]);
            let (stdout, stderr) = common::text(&out);
            let code = out.status.code().expect("an exit code, not a signal");
            assert!(!stderr.contains("panicked"), "{what}, {command}: {stderr}");
            if code == 0 {
                let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
                let mut all = Vec::new();
                numbers(&v, &mut all);
                assert!(
                    all.iter().all(|x| x.is_finite()),
                    "{what}, {command}: {stdout}"
                );
                if command == "identify" {
                    // Every applying method's parameters are physical.
                    for (name, m) in v["methods"].as_object().unwrap() {
                        let Some(params) = m["params"].as_object() else {
                            continue;
                        };
                        for (p, e) in params {
                            let x = e["value"].as_f64().unwrap();
                            assert!(x >= 0.0, "{what}: {name} {p} = {x}");
                            if p == "J" {
                                assert!(x < 10.0, "{what}: {name} J = {x} kg·m²");
                            }
                        }
                    }
                }
            } else {
                // A reason a user can act on, on one line.
                assert_eq!(stderr.trim_end().lines().count(), 1, "{what}: {stderr}");
                assert!(stderr.len() > 40, "{what}: {stderr}");
            }
            if command == "identify" {
                assert!(codes.contains(&code), "{what}: exit {code}: {stderr}");
            } else {
                assert!(
                    [0, 4].contains(&code),
                    "{what}, diagnose: exit {code}: {stderr}"
                );
            }
        }
    }
}
