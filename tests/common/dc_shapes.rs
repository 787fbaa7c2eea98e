//! DC records of the shapes a rig engineer brings that motorbench's own
//! bench never makes: short holds, a ringing motor, a ramp, a PRBS and a
//! closed speed loop. The plant is the model's exact simulation; the
//! sensors are a 12-bit ADC on voltage and current (with half a code of
//! analog noise) and a 1024-line quadrature encoder whose count
//! difference per sample is the speed reading.
#![allow(dead_code)]

use std::fmt::Write;
use std::path::{Path, PathBuf};

use motorbench::model::{DcMotor, DcParams, DcState, Terminal};
use motorbench::record::{DcSegment, Record, SegmentKind};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

/// Sample interval, s (2 kHz).
pub const DT: f64 = 5e-4;

/// Encoder counts per revolution (1024 lines, quadrature).
const COUNTS: f64 = 4096.0;

/// A ringing motor: τm = Ra·J/K² = 0.8 ms against τe = 5 ms, complex poles
/// near 80 Hz.
pub const RINGING: DcParams = DcParams {
    ra: 2.0,
    la: 0.01,
    k: 0.5,
    j: 1e-4,
    f: 1e-5,
    tst: 0.01,
};

/// How the voltage is made over the record.
pub enum Drive {
    /// Levels held for the given time each, from rest.
    Levels(Vec<f64>, f64),
    /// `u(t)` over the given duration from rest, cut into three segments.
    Open(Box<dyn Fn(f64) -> f64>, f64),
    /// A PI speed loop on the encoder reading tracking `ω*(t)`, its output
    /// (limited to ±limit) the voltage, over the given duration (three
    /// segments).
    SpeedLoop {
        reference: Box<dyn Fn(f64) -> f64>,
        kp: f64,
        ki: f64,
        limit: f64,
        seconds: f64,
    },
}

/// A record of `truth` under `drive`, with the sensors above (seeded).
pub fn record(truth: &DcParams, drive: &Drive, seed: u64) -> Record {
    let motor = DcMotor::new(*truth, DT).unwrap();
    let mut rng = StdRng::seed_from_u64(seed);
    let (n, bounds): (usize, Vec<usize>) = match drive {
        Drive::Levels(levels, hold) => {
            let per = (hold / DT).round() as usize;
            (
                levels.len() * per + 1,
                (0..=levels.len()).map(|s| s * per).collect(),
            )
        }
        Drive::Open(_, s) | Drive::SpeedLoop { seconds: s, .. } => {
            // Three segments (the diagnosis holds each out in turn).
            let n = (s / DT).round() as usize;
            (n, vec![0, n / 3, 2 * n / 3, n - 1])
        }
    };
    // Exact plant; the controller reads the quantised speed.
    let (mut u, mut i, mut angle) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut x = DcState::default();
    let (mut integral, mut last_count, mut w_read) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let t = k as f64 * DT;
        u[k] = match drive {
            Drive::Levels(levels, _) => {
                levels[(k.saturating_sub(1) / (bounds[1])).min(levels.len() - 1)]
            }
            Drive::Open(f, _) => f(t),
            Drive::SpeedLoop {
                reference,
                kp,
                ki,
                limit,
                ..
            } => {
                let e = reference(t) - w_read;
                let out = kp * e + ki * integral;
                if out.abs() < *limit {
                    integral += e * DT;
                }
                out.clamp(-limit, *limit)
            }
        };
        x = motor.step(&x, Terminal::Driven(u[k]));
        i[k] = x.current;
        angle[k] = x.angle;
        let count = (x.angle * COUNTS / std::f64::consts::TAU).floor();
        w_read = (count - last_count) * std::f64::consts::TAU / COUNTS / DT;
        last_count = count;
    }
    let adc = |y: &[f64], rng: &mut StdRng| {
        let peak = y.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let lsb = 2.0 * (1.5 * peak).max(1e-3) / 4096.0;
        let noise = Normal::new(0.0, 0.5 * lsb).unwrap();
        y.iter()
            .map(|v| ((v + noise.sample(rng)) / lsb).round() * lsb)
            .collect::<Vec<f64>>()
    };
    let (u_read, i_read) = (adc(&u, &mut rng), adc(&i, &mut rng));
    let counts: Vec<f64> = angle
        .iter()
        .map(|a| (a * COUNTS / std::f64::consts::TAU).floor())
        .collect();
    let w: Vec<f64> = (0..n)
        .map(|k| {
            let before = if k == 0 { 0.0 } else { counts[k - 1] };
            (counts[k] - before) * std::f64::consts::TAU / COUNTS / DT
        })
        .collect();
    let segments = bounds
        .windows(2)
        .enumerate()
        .map(|(s, b)| {
            let r = b[0]..=b[1].min(n - 1);
            DcSegment {
                index: s as u32,
                kind: Some(SegmentKind::DcStep),
                label: format!("part {s}"),
                time: r.clone().map(|k| k as f64 * DT).collect(),
                voltage: u_read[r.clone()].to_vec(),
                current: i_read[r.clone()].to_vec(),
                speed: w[r].to_vec(),
            }
        })
        .collect();
    Record {
        segments,
        ..Default::default()
    }
}

/// The shapes, each with its motor: name, truth, drive.
pub fn shapes() -> Vec<(&'static str, DcParams, Drive)> {
    let seed = DcParams::SEED_TABLE4_MOMENTS;
    let tau = seed.tau_m().max(seed.tau_e());
    let prbs = |t: f64| {
        // A 9-bit maximal-length sequence clocked every 20 ms.
        let mut reg: u16 = 0x1ff;
        let steps = (t / 0.02) as usize;
        for _ in 0..steps % 511 {
            let bit = ((reg >> 8) ^ (reg >> 4)) & 1;
            reg = ((reg << 1) | bit) & 0x1ff;
        }
        if reg & 1 == 1 {
            220.0
        } else {
            80.0
        }
    };
    vec![
        ("table2", seed, Drive::Levels(vec![60.0, 248.0], 0.31)),
        (
            "staircase_3tau",
            seed,
            Drive::Levels(vec![60.0, 248.0, 107.0, 201.0, 150.0], 3.0 * tau),
        ),
        (
            "ringing",
            RINGING,
            Drive::Levels(vec![12.0, 48.0, 24.0, 40.0], 0.05),
        ),
        (
            "ramp",
            seed,
            Drive::Open(
                Box::new(|t: f64| {
                    if t < 0.4 {
                        40.0 + 500.0 * t
                    } else {
                        240.0 - 450.0 * (t - 0.4)
                    }
                }),
                0.6,
            ),
        ),
        ("prbs", seed, Drive::Open(Box::new(prbs), 0.6)),
        (
            "speed_loop",
            seed,
            Drive::SpeedLoop {
                reference: Box::new(|t: f64| {
                    if t < 0.2 {
                        60.0
                    } else if t < 0.4 {
                        160.0
                    } else {
                        100.0
                    }
                }),
                kp: 2.0,
                ki: 40.0,
                limit: 300.0,
                seconds: 0.6,
            },
        ),
    ]
}

/// One CSV per segment in `dir` (the contract's columns, floats in full
/// precision), in segment order.
pub fn write_csvs(record: &Record, dir: &Path) -> Vec<PathBuf> {
    record
        .segments
        .iter()
        .map(|seg| {
            let mut text = format!(
                "# motorbench segment {} kind=dc_step label={}\n",
                seg.index, seg.label
            );
            text.push_str("time_s,armature_voltage_V,armature_current_A,speed_rad_s\n");
            for k in 0..seg.time.len() {
                writeln!(
                    text,
                    "{:?},{:?},{:?},{:?}",
                    seg.time[k], seg.voltage[k], seg.current[k], seg.speed[k]
                )
                .unwrap();
            }
            let path = dir.join(format!("segment-{}.csv", seg.index));
            std::fs::write(&path, text).unwrap();
            path
        })
        .collect()
}
