//! Which sample interval a DC record's voltage reading belongs to.
//!
//! motorbench's models read the voltage at `t[k]` as the voltage applied
//! over `(t[k−1], t[k]]`: the current at `t[k]` has already answered it,
//! as the bench records (and as the simulators of the blind benchmark
//! write). A digital controller that logs the command it issues at the
//! instant it samples writes the voltage applied over `(t[k], t[k+1]]`
//! at `t[k]` instead: the column then leads the current by one sample.
//! Where the voltage changes at every sample (a closed loop, a PRBS) that
//! one sample is a large share of each increment of the current, and the
//! fits bend the inductance and the friction to it (on a
//! gym-electric-motor speed loop shifted so: La 35 % low, Tst twice the
//! truth, the held-out NRMSE four times its own).
//!
//! The test: regress the current's increment `i[k] − i[k−1]` on
//! `i[k−1]`, `ω[k−1]`, a constant, and the voltage readings at `t[k]` and
//! at `t[k−1]`. In the exact zero-order-hold model of the bench's
//! convention the increment depends on the reading at `t[k]` only; with
//! the command logged as issued, on the one at `t[k−1]` only. A current
//! sensor that is one sample late looks the same (the blind benchmark's
//! sensor-lag cases include one), and a lagging sensor spreads the answer
//! over both. So the record is not changed on this evidence: where the
//! reading at `t[k]` has no part in the increment (its coefficient within
//! [`NO_PART`] standard errors of zero) and the one at `t[k−1]` clearly
//! has ([`CLEAR_PART`]), the report says so and how to align the column;
//! `--voltage-as-issued` moves it one sample later, for a user who knows
//! that the logger writes the command as it is issued.

use nalgebra::{DMatrix, DVector};

use super::identify::is_coastdown;
use super::{cut_at_time_gaps, fill_missing_samples, split_single_segment};
use crate::record::{DcSegment, Record, SegmentKind};

/// A DC record read from files, made ready for the DC methods as every
/// command that reads one does (`identify`, `diagnose`, `blind score`):
/// samples a logger dropped one or two at a time put back
/// ([`fill_missing_samples`]), a test held in one segment split
/// ([`split_single_segment`]), segments cut at longer gaps in their time
/// ([`cut_at_time_gaps`]); the voltage moved one
/// sample later when `voltage_as_issued`, else a note where the column
/// seems to lead the current ([`voltage_timing`]).
pub fn prepare_dc_record(record: Record, voltage_as_issued: bool) -> Record {
    let mut record = cut_at_time_gaps(split_single_segment(fill_missing_samples(record)));
    if voltage_as_issued {
        shift_voltage_one_sample_later(&mut record);
        record.notes.push(
            "the voltage column was moved one sample later (--voltage-as-issued): its reading \
             at t[k] is taken as the voltage applied over (t[k-1], t[k]]"
                .into(),
        );
    } else if let Some(t) = voltage_timing(&record).filter(VoltageTiming::leads_by_one_sample) {
        record.notes.push(t.note());
    }
    record
}

/// A coefficient within this many standard errors of zero has no part.
pub const NO_PART: f64 = 3.0;

/// A coefficient beyond this many standard errors has a clear part.
pub const CLEAR_PART: f64 = 10.0;

/// Fewest increments the test needs.
const MIN_ROWS: usize = 50;

/// The regression's answer: the increment's coefficients on the voltage
/// readings at `t[k]` and `t[k−1]`, each in its standard errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VoltageTiming {
    /// t statistic of the reading at `t[k]`.
    pub same_sample: f64,
    /// t statistic of the reading at `t[k−1]`.
    pub previous_sample: f64,
    /// Increments regressed.
    pub rows: usize,
}

impl VoltageTiming {
    /// Whether the voltage column leads the current by one sample.
    pub fn leads_by_one_sample(&self) -> bool {
        self.same_sample.abs() < NO_PART && self.previous_sample > CLEAR_PART
    }

    /// The report's note on a column that leads the current.
    fn note(&self) -> String {
        format!(
            "the current's increments answer the voltage read one sample earlier (t = {:.1}) \
             and not the one read at the same instant (t = {:.1}, over {} increments): the \
             voltage column leads the current by one sample. Either the logger writes the \
             command as it issues it (motorbench reads the voltage at t[k] as the one applied \
             over (t[k-1], t[k]]; --voltage-as-issued moves the column one sample later), or \
             the current sensor is one sample late (`diagnose` may then name sensor_lag)",
            self.previous_sample, self.same_sample, self.rows
        )
    }
}

fn driven(seg: &DcSegment) -> bool {
    seg.kind != Some(SegmentKind::DcCoastdown) && !is_coastdown(seg) && seg.time.len() > 2
}

/// The regression over every driven segment; `None` with too few
/// increments or when the voltage readings do not vary enough to tell.
pub fn voltage_timing(record: &Record) -> Option<VoltageTiming> {
    let rows: usize = record
        .segments
        .iter()
        .filter(|s| driven(s))
        .map(|s| s.time.len() - 1)
        .sum();
    if rows < MIN_ROWS {
        return None;
    }
    const COLS: usize = 5;
    let mut x = DMatrix::<f64>::zeros(rows, COLS);
    let mut y = DVector::<f64>::zeros(rows);
    let mut r = 0;
    for seg in record.segments.iter().filter(|s| driven(s)) {
        for k in 1..seg.time.len() {
            let row = [
                seg.voltage[k],
                seg.voltage[k - 1],
                seg.current[k - 1],
                seg.speed[k - 1],
                1.0,
            ];
            for (c, v) in row.iter().enumerate() {
                x[(r, c)] = *v;
            }
            y[r] = seg.current[k] - seg.current[k - 1];
            r += 1;
        }
    }
    // Columns scaled to unit norm, so that the normal equations' inverse is
    // well conditioned whatever the units.
    let scale: Vec<f64> = (0..COLS).map(|c| x.column(c).norm().max(1e-300)).collect();
    for (c, s) in scale.iter().enumerate() {
        x.column_mut(c).scale_mut(1.0 / s);
    }
    let xtx = x.transpose() * &x;
    let inv = xtx.try_inverse()?;
    let beta = &inv * (x.transpose() * &y);
    let resid = &y - &x * &beta;
    let s2 = resid.norm_squared() / (rows - COLS) as f64;
    let t = |c: usize| {
        let se = (s2 * inv[(c, c)]).sqrt();
        beta[c] / se
    };
    let (same, previous) = (t(0), t(1));
    (same.is_finite() && previous.is_finite()).then_some(VoltageTiming {
        same_sample: same,
        previous_sample: previous,
        rows,
    })
}

/// Move every driven segment's voltage one sample later: the reading at
/// `t[k]` becomes the one logged at `t[k−1]`.
fn shift_voltage_one_sample_later(record: &mut Record) {
    for seg in record.segments.iter_mut().filter(|s| driven(s)) {
        // The first sample's interval began before the segment: its own
        // reading is the best guess of what was applied then.
        seg.voltage.rotate_right(1);
        seg.voltage[0] = seg.voltage[1];
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::DcParams;
    use nalgebra::{Vector2, Vector3};
    use rand::rngs::StdRng;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// A speed-loop-like record: the voltage changes at every sample
    /// (a random walk around 20 V), the motor answers it by the exact
    /// zero-order hold of the bench's convention; 0.05 A of current noise;
    /// two segments of 1000 samples.
    fn record(seed: u64) -> Record {
        let p = DcParams {
            ra: 1.0,
            la: 5e-3,
            k: 0.1,
            j: 1e-4,
            f: 1e-5,
            tst: 0.0,
        };
        let dt = 5e-4;
        let motor = crate::model::DcMotor::new(p, dt).unwrap();
        let zoh = motor.driven_zoh();
        let mut rng = StdRng::seed_from_u64(seed);
        let step = Normal::new(0.0, 1.0).unwrap();
        let noise = Normal::new(0.0, 0.05).unwrap();
        let (mut i, mut w, mut u) = (0.0f64, 0.0f64, 20.0f64);
        let mut seg = DcSegment {
            kind: Some(SegmentKind::DcStep),
            ..DcSegment::default()
        };
        for k in 0..2000 {
            u = (u + step.sample(&mut rng)).clamp(0.0, 40.0);
            let x = zoh.step(&Vector3::new(i, w, 0.0), &Vector2::new(u, 0.0));
            (i, w) = (x[0], x[1]);
            seg.time.push(k as f64 * dt);
            seg.voltage.push(u);
            seg.current.push(i + noise.sample(&mut rng));
            seg.speed.push(w);
        }
        // Two segments, so that nothing splits the record.
        let half = |range: std::ops::Range<usize>, index: u32| DcSegment {
            index,
            kind: seg.kind,
            label: format!("segment {index}"),
            time: seg.time[range.clone()].to_vec(),
            voltage: seg.voltage[range.clone()].to_vec(),
            current: seg.current[range.clone()].to_vec(),
            speed: seg.speed[range].to_vec(),
        };
        Record {
            segments: vec![half(0..1000, 0), half(1000..2000, 1)],
            ..Record::default()
        }
    }

    /// A logger that drops a sample in forty (and two in a row once): the
    /// samples put back, output error's K and Ra are what the whole
    /// record gives; left out, every later sample stands early against
    /// the model.
    #[test]
    fn a_record_that_drops_samples_fits_as_the_whole_one() {
        let whole = record(4);
        let mut dropped = whole.clone();
        for seg in &mut dropped.segments {
            let keep: Vec<bool> = (0..seg.time.len())
                .map(|k| k < 2 || !(k % 40 == 17 || k == 618))
                .collect();
            for v in [
                &mut seg.time,
                &mut seg.voltage,
                &mut seg.current,
                &mut seg.speed,
            ] {
                let mut it = keep.iter();
                v.retain(|_| *it.next().unwrap());
            }
        }
        let fit = |r: Record| {
            let id = crate::machine::dc::identify::identify_dc(&prepare_dc_record(r, false));
            let oe = &id.report.methods["output_error"];
            let p = |name: &str| oe.params.as_ref().expect("output error applies")[name].value;
            (
                p("K"),
                p("Ra"),
                oe.validation_nrmse.expect("a held-out score"),
            )
        };
        let (k, ra, held_out) = fit(whole);
        let (k_dropped, ra_dropped, held_out_dropped) = fit(dropped);
        assert!(
            (k - 0.1).abs() < 1e-3 && (ra - 1.0).abs() < 1e-2,
            "{k} {ra}"
        );
        assert!(
            (k_dropped / k - 1.0).abs() < 2e-3 && (ra_dropped / ra - 1.0).abs() < 5e-3,
            "K {k_dropped} against {k}, Ra {ra_dropped} against {ra}"
        );
        // Left out, the held-out NRMSE doubles (0.0174 to 0.0351).
        assert!(
            held_out_dropped < 1.15 * held_out,
            "held-out NRMSE {held_out_dropped} against {held_out}"
        );
    }

    #[test]
    fn a_record_in_the_benchs_convention_gets_no_note() {
        let r = record(1);
        let t = voltage_timing(&r).unwrap();
        assert!(!t.leads_by_one_sample(), "{t:?}");
        assert!(t.same_sample > CLEAR_PART, "{t:?}");
        let kept = prepare_dc_record(r.clone(), false);
        assert_eq!(kept, r);
    }

    #[test]
    fn a_command_logged_as_issued_is_noted_and_moved_on_request() {
        let r = record(2);
        let mut led = r.clone();
        // The column one sample early: the reading at t[k] is what is
        // applied over (t[k], t[k+1]].
        for seg in &mut led.segments {
            seg.voltage.rotate_left(1);
        }
        let t = voltage_timing(&led).unwrap();
        assert!(t.leads_by_one_sample(), "{t:?}");
        let noted = prepare_dc_record(led.clone(), false);
        assert_eq!(noted.segments, led.segments);
        assert!(noted.notes[0].contains("leads the current by one sample"));
        let moved = prepare_dc_record(led, true);
        for (m, r) in moved.segments.iter().zip(&r.segments) {
            assert_eq!(m.voltage[1..], r.voltage[1..]);
        }
        assert!(moved.notes[0].contains("--voltage-as-issued"));
        assert!(!voltage_timing(&moved).unwrap().leads_by_one_sample());
    }

    #[test]
    fn steps_that_rarely_change_tell_nothing() {
        let mut r = record(3);
        for (k, u) in r.segments[0].voltage.iter_mut().enumerate() {
            *u = if k < 500 { 10.0 } else { 20.0 };
        }
        r.segments[1].voltage.fill(15.0);
        let t = voltage_timing(&r);
        assert!(t.is_none_or(|t| !t.leads_by_one_sample()), "{t:?}");
    }
}
