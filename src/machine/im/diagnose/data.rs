//! A record's slip sweeps as the IM diagnosis reads them: per-phase
//! operating points in recording order, which of them run free (no-load
//! readings), their supply-voltage groups, the heat index, the noise
//! weights and the held-out folds.

use super::effects::PointInput;
use super::standard_points::SAME_FREQUENCY;
use crate::diagnose::{DiagnoseError, DiagnoseOptions};
use crate::identify::{sweep_of, SlipSweep};
use crate::model::Connection;
use crate::record::{OperatingPoint, Record};

/// Segments whose mean line voltages differ by less than this fraction
/// are one supply voltage.
const SAME_VOLTAGE: f64 = 0.03;
/// Interleaved folds on a single sweep.
const INTERLEAVED_FOLDS: usize = 5;
/// Fewest operating points a diagnosis works with.
pub const MIN_POINTS: usize = 12;
/// Reading floor of a channel's noise scale, as a fraction of its largest
/// reading: a meter's "digits" (range-related) error, which keeps the
/// weight of a near-zero reading finite.
const DIGIT_FLOOR: f64 = 0.01;

/// The operating points of a record, per phase.
#[derive(Debug, Clone, PartialEq)]
pub struct SweepSet {
    /// Winding connection used to go from line to phase quantities.
    pub connection: Connection,
    /// Model inputs per point (slip, phase voltage, heat index).
    pub inputs: Vec<PointInput>,
    /// Measured phase current, A.
    pub current: Vec<f64>,
    /// Measured three-phase input power, W.
    pub power: Vec<f64>,
    /// Segment of each point.
    pub segment: Vec<u32>,
    /// Whether each point runs free (a no-load reading: slip not
    /// measured; [`PointInput::free_running`]).
    pub free_running: Vec<bool>,
    /// Supply-voltage group of each point (index into `group_voltage`).
    pub group: Vec<usize>,
    /// Mean line voltage of each group, V.
    pub group_voltage: Vec<f64>,
    /// Scale of each current reading: `|I| + floor`, A.
    pub scale_i: Vec<f64>,
    /// Scale of each power reading: `|P| + floor`, W.
    pub scale_p: Vec<f64>,
    /// Measured shaft torque, N·m, where the record has a torque column
    /// and the synchronous speed is known.
    pub torque: Vec<Option<f64>>,
    /// Synchronous (mechanical) speed of each point, rad/s (NaN unknown).
    pub sync_speed: Vec<f64>,
    /// Scale of each torque reading: `|T| + floor`, N·m.
    pub scale_t: Vec<f64>,
    /// Relative noise of the torque, once estimated.
    pub sigma_t: f64,
    /// Relative noise of the current (σ per unit of scale), once estimated.
    pub sigma_i: f64,
    /// Relative noise of the power, once estimated.
    pub sigma_p: f64,
    /// Line current per phase current (1 star, √3 delta).
    pub line_per_phase: f64,
    /// Warnings about the data.
    pub warnings: Vec<String>,
}

/// What the diagnosis makes of the winding thermometer: where every
/// point has a temperature, each point's `Rs` is scaled to it
/// ([`SlipSweep::rs_scale`], from the first point's), so the measured
/// heating is known to every model; where only some have one, none is
/// used (a scale against an unknown temperature would be a guess).
/// `None` without a thermometer.
fn thermometer_note(sweep: &SlipSweep) -> Option<String> {
    let (first, [lo, hi], count) = sweep.thermometer()?;
    let n = sweep.points.len();
    Some(if count == n {
        format!(
            "the stator resistance follows the winding thermometer ({lo:.1} to {hi:.1} °C over \
             the points): Rs is given at the first point's {first:.1} °C, each point's scaled \
             by copper's α"
        )
    } else {
        format!(
            "the winding temperature is on {count} of the {n} operating points: not used (the \
             diagnosis scales the stator resistance per point only where every point has \
             one); Rs is one value over the record"
        )
    })
}

impl SweepSet {
    /// Read the record's operating points; those of the segments
    /// `free_running` run free.
    pub fn from_record(
        record: &Record,
        free_running: &[u32],
        options: &DiagnoseOptions,
    ) -> Result<SweepSet, DiagnoseError> {
        let mut warnings = Vec::new();
        let connection = options
            .connection
            .or_else(|| {
                record
                    .meta
                    .as_ref()
                    .and_then(|m| m.nameplate.get("connection"))
                    .and_then(|v| v.as_str())
                    .and_then(Connection::parse)
            })
            .unwrap_or_else(|| {
                warnings.push(
                    "no winding connection given (--connection or the nameplate's \"connection\"): \
                     star assumed; per-phase impedances scale by 3 between star and delta"
                        .into(),
                );
                Connection::Star
            });
        let sweep = sweep_of(record, connection);
        sweep
            .validate()
            .map_err(|e| DiagnoseError::NotEnoughData(format!("im_slip_sweep record: {e}")))?;
        let n = sweep.points.len();
        if n < MIN_POINTS {
            return Err(DiagnoseError::NotEnoughData(format!(
                "{n} operating points; the IM diagnosis needs at least {MIN_POINTS} \
                 (a sweep from near synchronous speed to locked rotor)"
            )));
        }
        let d = sweep.phase_data();
        // Voltage groups by segment mean.
        let mut segs: Vec<u32> = sweep.points.iter().map(|p| p.segment).collect();
        segs.sort_unstable();
        segs.dedup();
        let mut group_voltage: Vec<f64> = Vec::new();
        let mut seg_group = Vec::new();
        // The sweeps' segments first; a no-load test spans voltages and is
        // a group of its own (at its mean), after them.
        segs.sort_by_key(|s| free_running.contains(s));
        for &s in &segs {
            let vs: Vec<f64> = sweep
                .points
                .iter()
                .filter(|p| p.segment == s)
                .map(|p| p.line_voltage)
                .collect();
            let mean = vs.iter().sum::<f64>() / vs.len() as f64;
            let g = group_voltage
                .iter()
                .position(|&gv| (gv - mean).abs() <= SAME_VOLTAGE * gv.max(mean))
                .filter(|_| !free_running.contains(&s));
            let g = g.unwrap_or_else(|| {
                group_voltage.push(mean);
                group_voltage.len() - 1
            });
            seg_group.push((s, g));
        }
        let group: Vec<usize> = sweep
            .points
            .iter()
            .map(|p| {
                seg_group
                    .iter()
                    .find(|(s, _)| *s == p.segment)
                    .map_or(0, |(_, g)| *g)
            })
            .collect();
        // Heat index: I² accumulated in recording order, mid-point rule.
        let total: f64 = d.current.iter().map(|i| i * i).sum();
        let mut acc = 0.0;
        let heat: Vec<f64> = d
            .current
            .iter()
            .map(|i| {
                let h = acc + 0.5 * i * i;
                acc += i * i;
                h / total
            })
            .collect();
        let ratios = frequency_ratios(&record.operating_points);
        let free: Vec<bool> = sweep
            .points
            .iter()
            .map(|p| free_running.contains(&p.segment))
            .collect();
        warnings.extend(thermometer_note(&sweep));
        let rs_scale = sweep.rs_scale();
        let inputs = (0..n)
            .map(|k| PointInput {
                heat: heat[k],
                freq_ratio: ratios[k],
                free_running: free[k],
                rs_scale: rs_scale.get(k).copied().unwrap_or(1.0),
                ..PointInput::at(d.slip[k], d.voltage[k])
            })
            .collect();
        let floor = |v: &[f64]| DIGIT_FLOOR * v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let (fi, fp) = (floor(&d.current), floor(&d.power));
        let poles = record
            .meta
            .as_ref()
            .and_then(|m| m.nameplate.get("poles"))
            .and_then(serde_json::Value::as_f64);
        let (torque, sync_speed) = shaft_torque(&record.operating_points, &ratios, &free, poles);
        if sweep.points.iter().any(|p| p.torque.is_some()) && torque.iter().all(Option::is_none) {
            warnings.push(
                "the torque column is not used: neither a speed reading nor the nameplate's \
                 \"poles\" (with the supply frequency) gives the synchronous speed it needs"
                    .into(),
            );
        }
        let measured: Vec<f64> = torque.iter().flatten().copied().collect();
        let ft = floor(&measured);
        let scale_t = torque
            .iter()
            .map(|t| t.map_or(1.0, |t| t.abs() + ft))
            .collect();
        let known = || {
            d.slip
                .iter()
                .zip(&free)
                .filter(|(_, f)| !**f)
                .map(|(s, _)| *s)
        };
        let has_low = known().any(|s| s < 0.05);
        let has_high = known().any(|s| s > 0.5);
        if !(has_low && has_high) {
            warnings.push(
                "the sweep does not reach both near-synchronous speed (slip < 0.05) and high slip (> 0.5): \
                 regions outside it cannot be diagnosed"
                    .into(),
            );
        }
        Ok(SweepSet {
            connection,
            inputs,
            scale_i: d.current.iter().map(|i| i.abs() + fi).collect(),
            scale_p: d.power.iter().map(|p| p.abs() + fp).collect(),
            torque,
            sync_speed,
            scale_t,
            sigma_t: 1.0,
            current: d.current,
            power: d.power,
            segment: sweep.points.iter().map(|p| p.segment).collect(),
            free_running: free,
            group,
            group_voltage,
            sigma_i: 1.0,
            sigma_p: 1.0,
            line_per_phase: connection.line_current(1.0),
            warnings,
        })
    }

    /// Number of points.
    pub fn len(&self) -> usize {
        self.inputs.len()
    }

    /// Largest phase voltage and current.
    pub fn maxima(&self) -> (f64, f64) {
        let v = self.inputs.iter().fold(0.0f64, |m, p| m.max(p.voltage));
        let i = self.current.iter().fold(0.0f64, |m, x| m.max(*x));
        (v, i)
    }

    /// What the record holds of the tests that separate look-alikes.
    pub fn held_tests(&self) -> super::verdict::HeldTests {
        super::verdict::HeldTests {
            several_voltages: self.several_voltages(),
            no_load: self.free_running.iter().any(|f| *f),
            torque: self.torque.iter().any(Option::is_some),
        }
    }

    /// Whether the record holds sweeps at two or more supply voltages, or
    /// a no-load test over a range of voltages.
    pub fn several_voltages(&self) -> bool {
        let (lo, hi) = self
            .inputs
            .iter()
            .zip(&self.free_running)
            .filter(|(_, f)| **f)
            .fold((f64::INFINITY, 0.0f64), |(lo, hi), (p, _)| {
                (lo.min(p.voltage), hi.max(p.voltage))
            });
        self.sweep_voltages() >= 2 || hi > lo * (1.0 + SAME_VOLTAGE)
    }

    /// How many supply voltages the points of known slip have.
    fn sweep_voltages(&self) -> usize {
        let mut g: Vec<usize> = self.known_slip().iter().map(|&k| self.group[k]).collect();
        g.sort_unstable();
        g.dedup();
        g.len()
    }

    /// The points of known slip (every point but the free-running ones).
    pub fn known_slip(&self) -> Vec<usize> {
        (0..self.len()).filter(|&k| !self.free_running[k]).collect()
    }

    /// Whether any point has a measured shaft torque.
    pub fn has_torque(&self) -> bool {
        self.torque.iter().any(Option::is_some)
    }

    /// Whether any point runs free (the record has a no-load test).
    pub fn has_free_running(&self) -> bool {
        self.free_running.iter().any(|f| *f)
    }

    /// Held-out folds: the points each fold leaves out, and a description.
    ///
    /// Interleaved points, stratified by sweep: within each segment the
    /// points ranked by slip go to fold `rank mod k`, so that every fold
    /// trains on every supply voltage and on the whole slip range.
    /// Leaving a whole voltage out would test extrapolation to a voltage
    /// the fit never saw, and an effect that shows only at the highest
    /// voltage (main-flux or leakage saturation) cannot be learnt then:
    /// leave-one-voltage-out denies exactly the effects a second voltage is
    /// taken for.
    pub fn folds(&self) -> (Vec<Vec<usize>>, String) {
        let k = INTERLEAVED_FOLDS.min(self.len() / 4).max(2);
        let mut folds = vec![Vec::new(); k];
        let mut segs = self.segment.clone();
        segs.sort_unstable();
        segs.dedup();
        for s in segs {
            let mut idx: Vec<usize> = (0..self.len()).filter(|&j| self.segment[j] == s).collect();
            idx.sort_by(|&a, &b| self.inputs[a].slip.total_cmp(&self.inputs[b].slip));
            for (r, j) in idx.into_iter().enumerate() {
                folds[r % k].push(j);
            }
        }
        for f in &mut folds {
            f.sort_unstable();
        }
        let voltages = self.sweep_voltages();
        let no_load = self.group_voltage.len() - voltages;
        (
            folds,
            format!(
                "interleaved points ({k} folds by slip rank within each sweep, {} supply \
                 voltage{}{})",
                voltages,
                if voltages == 1 { "" } else { "s" },
                match no_load {
                    0 => String::new(),
                    1 => " and a no-load test".into(),
                    n => format!(" and {n} no-load tests"),
                }
            ),
        )
    }
}

/// Each point's measured shaft torque (where it has one and the
/// synchronous speed is known) and synchronous speed, rad/s: the median of
/// `speed/(1 − s)` over the points of known slip below 0.9 at the
/// reference frequency, else `2π·f/(poles/2)` from the nameplate's
/// `poles`, scaled by each point's frequency ratio.
fn shaft_torque(
    points: &[OperatingPoint],
    ratios: &[f64],
    free: &[bool],
    poles: Option<f64>,
) -> (Vec<Option<f64>>, Vec<f64>) {
    let mut sync: Vec<f64> = points
        .iter()
        .zip(ratios)
        .zip(free)
        .filter(|((p, _), f)| !**f && p.slip < 0.9 && p.speed.is_finite() && p.speed > 0.0)
        .map(|((p, r), _)| p.speed / (1.0 - p.slip) / r)
        .collect();
    sync.sort_by(f64::total_cmp);
    let from_poles = || {
        let f = points
            .iter()
            .zip(ratios)
            .map(|(p, r)| p.frequency / r)
            .find(|f| f.is_finite() && *f > 0.0)?;
        let pairs = poles.filter(|p| *p >= 2.0)? / 2.0;
        Some(std::f64::consts::TAU * f / pairs)
    };
    let reference = sync.get(sync.len() / 2).copied().or_else(from_poles);
    let sync_speed: Vec<f64> = ratios
        .iter()
        .map(|r| reference.map_or(f64::NAN, |w| w * r))
        .collect();
    let torque = points
        .iter()
        .zip(&sync_speed)
        .zip(free)
        .map(|((p, w), f)| p.torque.filter(|t| t.is_finite() && w.is_finite() && !*f))
        .collect();
    (torque, sync_speed)
}

/// Each point's supply frequency over the reference, the frequency most
/// points share (the load test's: a reduced-frequency locked-rotor test
/// has a few points); 1 where a point or every point has none.
fn frequency_ratios(points: &[OperatingPoint]) -> Vec<f64> {
    let same = |a: f64, b: f64| (a - b).abs() <= SAME_FREQUENCY * a.abs().max(b.abs());
    let finite: Vec<f64> = points
        .iter()
        .map(|p| p.frequency)
        .filter(|f| f.is_finite() && *f > 0.0)
        .collect();
    let reference = finite
        .iter()
        .copied()
        .max_by_key(|&f| finite.iter().filter(|&&g| same(f, g)).count());
    points
        .iter()
        .map(|p| match reference {
            Some(f0) if p.frequency.is_finite() && p.frequency > 0.0 && !same(p.frequency, f0) => {
                p.frequency / f0
            }
            _ => 1.0,
        })
        .collect()
}
