//! The `im_slip_sweep` test: the supply at a fixed voltage and frequency,
//! the dynamometer stepping the shaft through a list of slips (denser near
//! 0, where the curves bend), one segment per supply voltage. At each point
//! the bench waits until current, power and speed have settled (detected
//! from the signals, not a fixed wait), averages a window of samples and
//! records it on `/bench/operating_point`; every raw sample goes to
//! `/sensor/*`.
//!
//! Safety: the sweep reads through the shared [`Sequencer`], so every batch
//! is checked with the test's [`crate::bench::SafetyMonitor`] (the limits, the
//! supervisor's checks, and the plan's winding heating budget
//! `∫ max(0, (I/I_rated)² − 1) dt` with a recovery time constant, an I²t
//! limit), a silent sensor ends the sweep after the stale-data timeout and
//! an operator stop ends it at once. The test stops with both stages in
//! their safe state first. Under the daemon's safety supervisor a failed
//! check is handed to the supervisor (see [`crate::bench::StopPath`]), which
//! latches the rig. A point whose current exceeds
//! `hot_current` (towards locked rotor) is held at most `hot_point_max_s`
//! and followed by a cool-down with the supply off: a real rig burns the
//! winding otherwise.

use super::standard_plan::StandardTestsPlan;
use crate::bench::sequencer::{safe_state_all, Halt, Read, Sequencer, SpeedChannel};
use crate::bench::{
    sensor_channels_with_speed, BenchError, HeatingBudget, Outcome, Progress, RecordSink,
    SafetyRules, SettleDetector, StopPath,
};
use crate::config::{Limits, Supervision};
use crate::identify::slip_grid;
use crate::record::{ChannelSpec, Entry, EventLevel, OperatingPoint, SegmentKind, SegmentPhase};
use motorbench_drivers::{ChannelInfo, DriverError, PowerStage, SensorStream};

/// The plan of a slip sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct ImSweepPlan {
    /// Supply line voltage of each segment, V.
    pub voltages: Vec<f64>,
    /// Slip set points, in the order run.
    pub slips: Vec<f64>,
    /// Supply frequency, Hz.
    pub frequency: f64,
    /// Pole pairs of the machine.
    pub pole_pairs: u32,
    /// Samples per settle window (two windows are compared).
    pub settle_window: usize,
    /// Relative tolerance of the settle test.
    pub settle_tolerance: f64,
    /// Samples averaged per operating point once settled.
    pub average_samples: usize,
    /// Longest wait for a point to settle, s.
    pub max_point_s: f64,
    /// Rated line current, A (the heating budget's reference).
    pub rated_current: f64,
    /// Abort above this line current, A.
    pub max_current: f64,
    /// Points above this line current are hot: time-limited, then cooled.
    pub hot_current: f64,
    /// Longest time at a hot point, s.
    pub hot_point_max_s: f64,
    /// Pause with the supply off after a hot point, s.
    pub cooldown_s: f64,
    /// Heating budget: the winding's excess heat
    /// `∫ max(0, (I/I_rated)² − 1) dt`, forgetting with
    /// [`ImSweepPlan::i2t_time_constant_s`], may not pass this, s (about
    /// 36 × the safe stall time at 6× rated current).
    pub max_i2t_s: f64,
    /// Time constant with which the heating budget recovers, s.
    pub i2t_time_constant_s: f64,
    /// Encoder counts per revolution (4 per line for quadrature).
    pub encoder_counts_per_rev: f64,
}

impl ImSweepPlan {
    /// A plan for a machine rated `line_voltage`, `line_current` at
    /// `frequency` with `pole_pairs`: sweeps at 100 % and 80 % voltage,
    /// 30 slips from 0.002 to 1, 25-sample settle windows at 0.2 %, 50
    /// samples averaged, hot points above twice rated current held at most
    /// 1.5 s and followed by 10 s off, abort at 8× rated current or past a
    /// heating budget of 300 s (recovering with 120 s), a 1024-line encoder.
    pub fn new(
        line_voltage: f64,
        line_current: f64,
        frequency: f64,
        pole_pairs: u32,
    ) -> ImSweepPlan {
        ImSweepPlan {
            voltages: vec![line_voltage, 0.8 * line_voltage],
            slips: slip_grid(30, 0.002),
            frequency,
            pole_pairs,
            settle_window: 25,
            settle_tolerance: 0.002,
            average_samples: 50,
            max_point_s: 5.0,
            rated_current: line_current,
            max_current: 8.0 * line_current,
            hot_current: 2.0 * line_current,
            hot_point_max_s: 1.5,
            cooldown_s: 10.0,
            max_i2t_s: 300.0,
            i2t_time_constant_s: 120.0,
            encoder_counts_per_rev: 4096.0,
        }
    }

    /// Synchronous speed, rad/s.
    pub fn synchronous_speed(&self) -> f64 {
        std::f64::consts::TAU * self.frequency / f64::from(self.pole_pairs.max(1))
    }

    /// The plan's winding heating budget.
    pub fn heating_budget(&self) -> HeatingBudget {
        HeatingBudget {
            rated_current: self.rated_current,
            max_i2t_s: self.max_i2t_s,
            time_constant_s: self.i2t_time_constant_s,
        }
    }

    /// The safety rules of a bare plan (no configuration file): the
    /// plan's current limit and heating budget, a voltage limit 10 %
    /// above its highest supply voltage, a speed limit 20 % above
    /// synchronous, and the `[supervisor]` defaults (the winding estimate
    /// rated at the plan's rated current). A configured sweep takes its
    /// rules from [`super::ImRunConfig::safety_rules`].
    pub fn safety_rules(&self) -> SafetyRules {
        let limits = Limits {
            max_voltage: 1.1 * self.voltages.iter().copied().fold(0.0, f64::max),
            max_current: self.max_current,
            max_speed: 1.2 * self.synchronous_speed(),
        };
        SafetyRules {
            limits,
            supervision: Supervision::defaults(&limits, self.rated_current),
            heating: Some(self.heating_budget()),
        }
    }
}

/// The mean speed over a window of encoder speed readings `(time, speed)`
/// (each the count change since the previous reading over its interval):
/// the least-squares slope of the angle they add up to against time, fitted
/// again without the readings off the first line by more than four robust
/// standard deviations (1.4826 × the median absolute residual) and more
/// than four counts (`rad_per_count`: so that the count's quantisation and
/// a still-settling shaft's curvature never count as outliers). The angle
/// is the count itself, so the slope averages its quantisation; a polled
/// count whose timestamp a stall threw off (a host busy for milliseconds)
/// is one outlier in the angle, where in the plain fit it tilts the line.
fn angle_slope(time: &[f64], speed: &[f64], rad_per_count: f64) -> f64 {
    let n = time.len().min(speed.len());
    if n < 3 {
        return speed[..n].iter().sum::<f64>() / n.max(1) as f64;
    }
    let angle = crate::identify::running_angle(&time[..n], &speed[..n]);
    let fit = |keep: &dyn Fn(usize) -> bool| {
        let idx: Vec<usize> = (0..n).filter(|&k| keep(k)).collect();
        let m = idx.len() as f64;
        let tm = idx.iter().map(|&k| time[k]).sum::<f64>() / m;
        let am = idx.iter().map(|&k| angle[k]).sum::<f64>() / m;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for &k in &idx {
            sxy += (time[k] - tm) * (angle[k] - am);
            sxx += (time[k] - tm).powi(2);
        }
        let slope = sxy / sxx;
        (slope, am - slope * tm)
    };
    let (w, a0) = fit(&|_| true);
    let residual = |k: usize| angle[k] - (a0 + w * time[k]);
    let mut abs: Vec<f64> = (0..n).map(|k| residual(k).abs()).collect();
    abs.sort_by(f64::total_cmp);
    let bound = (4.0 * 1.4826 * abs[n / 2]).max(4.0 * rad_per_count);
    if bound.is_nan() {
        return w;
    }
    let kept = (0..n).filter(|&k| residual(k).abs() <= bound).count();
    if kept < 3 || kept == n {
        return w;
    }
    fit(&|k| residual(k).abs() <= bound).0
}

/// The mean of the values present, `None` when none is.
pub(super) fn mean_of(values: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let (sum, n) = values
        .flatten()
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// Channels recorded for a sweep: every sensor channel, then the speed
/// derived from the encoder, then the supply-voltage and dynamometer-speed
/// commands.
pub fn sweep_channels(sensors: &[ChannelInfo], vfd_id: &str, dyno_id: &str) -> Vec<ChannelSpec> {
    let mut out = sensor_channels_with_speed(sensors);
    out.push(ChannelSpec::command("line_voltage", "V", vfd_id));
    out.push(ChannelSpec::command("dyno_speed", "rad/s", dyno_id));
    out
}

/// One reading of the quantities the sweep watches.
#[derive(Debug, Clone, Copy)]
pub(super) struct Reading {
    /// Data time of the batch that completed it, ns.
    pub t_ns: u64,
    pub voltage: f64,
    pub current: f64,
    pub power: f64,
    pub speed: Option<f64>,
    pub torque: Option<f64>,
    /// The DC source's voltage and current, where the rig has one.
    pub dc_voltage: f64,
    pub dc_current: f64,
    /// The winding thermometer's reading, °C, where the rig has one.
    pub winding_temperature: Option<f64>,
}

/// Where the plan's quantities are: sensor channels, then record channels.
pub(super) struct Indices {
    pub voltage: usize,
    pub current: usize,
    pub power: usize,
    pub torque: Option<usize>,
    /// The DC source's voltage and current sensor channels, where fitted.
    pub dc: Option<(usize, usize)>,
    /// The winding thermometer's sensor channel, where fitted.
    pub temperature: Option<usize>,
    pub vfd_rec: usize,
    pub dyno_rec: usize,
    /// The DC source's command record channel.
    pub dc_rec: usize,
    /// The supply-frequency command's record channel (a plan with a
    /// reduced-frequency locked-rotor test).
    pub frequency_rec: usize,
}

impl From<DriverError> for Halt {
    fn from(e: DriverError) -> Halt {
        Halt::Fault(format!("driver error: {e}"))
    }
}

/// A plan running on an induction-machine rig: the slip sweep's points,
/// and (`standard_plan`) the standard tests' readings.
pub(super) struct Sweep<'a> {
    pub plan: &'a ImSweepPlan,
    pub vfd: &'a mut dyn PowerStage,
    pub dyno: &'a mut dyn PowerStage,
    /// The DC source of the winding-resistance test, where fitted.
    pub dc: Option<&'a mut dyn PowerStage>,
    pub seq: Sequencer<'a>,
    pub ix: Indices,
    /// The latest value of each watched quantity: streams that poll
    /// devices separately deliver batches with some channels only.
    held: Reading,
    /// `(data time, speed)` of every encoder reading of the current point.
    speeds: Vec<(u64, f64)>,
    /// The index of the first slip-sweep segment.
    pub first_segment: usize,
    /// The mean winding temperature over the last steady point's
    /// averaging window, °C, where the rig reads one.
    pub window_temperature: Option<f64>,
    /// The encoder has been found to disagree with the dynamometer's
    /// speed (warned once a test).
    speed_disagrees: bool,
}

/// How far the encoder's speed at a steady load point may stray from the
/// speed the dynamometer holds, as a share of the synchronous speed,
/// before the sweep warns: a drive holds its speed to a few per cent; a
/// wrong encoder resolution, or an encoder that loses counts, is off by
/// a factor.
const SPEED_DISAGREEMENT: f64 = 0.1;

impl Sweep<'_> {
    pub fn t_ns(&self) -> u64 {
        self.seq.t_ns()
    }

    /// Next reading: batches are read through the [`Sequencer`] (recorded
    /// and checked as they come); a reading is made of the latest value of
    /// each quantity when a batch brings a new line current (with a rig
    /// whose meter and encoder are polled separately, batches carrying
    /// only the encoder update the speed).
    pub async fn read(&mut self) -> Result<Reading, Halt> {
        self.read_on(self.ix.current).await
    }

    /// As [`Sweep::read`], a reading made when a batch brings a new value
    /// of sensor channel `trigger`.
    pub async fn read_on(&mut self, trigger: usize) -> Result<Reading, Halt> {
        loop {
            let Read { batch, speed } = self.seq.next().await?;
            if let Some(w) = speed {
                self.held.speed = Some(w);
                self.speeds.push((batch.t_ns, w));
            }
            let get = |c: usize| batch.value(c);
            let h = &mut self.held;
            if let Some(v) = get(self.ix.voltage) {
                h.voltage = v;
            }
            if let Some(p) = get(self.ix.power) {
                h.power = p;
            }
            if let Some(t) = self.ix.torque.and_then(get) {
                h.torque = Some(t);
            }
            if let Some((v, i)) = self.ix.dc {
                h.dc_voltage = get(v).unwrap_or(h.dc_voltage);
                h.dc_current = get(i).unwrap_or(h.dc_current);
            }
            if let Some(t) = self.ix.temperature.and_then(get) {
                h.winding_temperature = Some(t);
            }
            if let Some(current) = get(self.ix.current) {
                h.current = current;
            }
            if get(trigger).is_none() {
                continue;
            }
            h.t_ns = batch.t_ns;
            return Ok(*h);
        }
    }

    /// Hold the point of `slip` until it settles, then average it; `None`
    /// when it did not settle in time (and was not hot).
    async fn point(
        &mut self,
        segment: u32,
        slip: f64,
    ) -> Result<Option<(OperatingPoint, bool)>, Halt> {
        let ws = self.plan.synchronous_speed();
        let target = (1.0 - slip) * ws;
        self.dyno.set_setpoint(target).await?;
        self.seq.command(self.ix.dyno_rec, target).await?;
        let what = format!("slip {slip:.4}");
        let point = self.steady(segment, &what).await?;
        if let Some((p, _)) = &point {
            self.check_speed(&what, p.speed, target).await?;
        }
        Ok(point)
    }

    /// Warn (once a test) when the encoder's speed at a steady point,
    /// `speed`, is not the speed the dynamometer holds, `target`: the
    /// slips of the test come from the encoder, so a wrong encoder
    /// resolution in the configuration, or an encoder that loses counts,
    /// would make every point's slip wrong without anything else showing
    /// it.
    async fn check_speed(&mut self, what: &str, speed: f64, target: f64) -> Result<(), Halt> {
        let ws = self.plan.synchronous_speed();
        if self.speed_disagrees
            || !speed.is_finite()
            || (speed - target).abs() <= SPEED_DISAGREEMENT * ws
        {
            return Ok(());
        }
        self.speed_disagrees = true;
        let ratio = if target.abs() > 1e-9 {
            format!(" ({:.2} times it)", speed / target)
        } else {
            String::new()
        };
        self.seq
            .event(
                EventLevel::Warn,
                format!(
                    "{what}: the encoder reads {speed:.1} rad/s where the dynamometer holds \
                     {target:.1} rad/s{ratio}: check the encoder's lines per revolution \
                     ({:.0} counts per revolution configured) and its wiring, or whether the \
                     dynamometer holds its speed; every slip of this test comes from the encoder",
                    self.plan.encoder_counts_per_rev
                ),
            )
            .await?;
        Ok(())
    }

    /// Wait until line current, input power and speed settle, then
    /// average them into a point of `segment`; `None` when they did not
    /// settle in time (and the point was not hot); `what` names the point
    /// in events. The bool: the point was hot.
    pub async fn steady(
        &mut self,
        segment: u32,
        what: &str,
    ) -> Result<Option<(OperatingPoint, bool)>, Halt> {
        let ws = self.plan.synchronous_speed();
        // Line current, input power and speed.
        let mut detector =
            SettleDetector::new(self.plan.settle_window, self.plan.settle_tolerance, 3);
        self.speeds.clear();
        let start = self.t_ns();
        let mut recent: Vec<Reading> = Vec::new();
        let mut hot = false;
        let settled = loop {
            let r = self.read().await?;
            hot |= r.current > self.plan.hot_current;
            recent.push(r);
            if recent.len() > self.plan.average_samples {
                recent.remove(0);
            }
            let w = r.speed.unwrap_or(f64::NAN);
            if w.is_finite() && detector.push(&[r.current, r.power, w]) {
                break true;
            }
            let elapsed = (self.t_ns() - start) as f64 * 1e-9;
            let limit = if hot {
                self.plan.hot_point_max_s
            } else {
                self.plan.max_point_s
            };
            if elapsed > limit {
                break false;
            }
        };
        let window = if settled {
            let mut w = Vec::with_capacity(self.plan.average_samples);
            while w.len() < self.plan.average_samples {
                let r = self.read().await?;
                let elapsed = (self.t_ns() - start) as f64 * 1e-9;
                w.push(r);
                if hot && elapsed > self.plan.hot_point_max_s {
                    break;
                }
            }
            w
        } else if hot {
            self.seq
                .event(
                    EventLevel::Warn,
                    format!(
                        "{what}: not settled within the hot-point limit {} s; the last {} samples averaged",
                        self.plan.hot_point_max_s,
                        recent.len()
                    ),
                )
                .await?;
            recent
        } else {
            self.seq
                .event(
                    EventLevel::Warn,
                    format!(
                        "{what}: not settled within {} s; point skipped",
                        self.plan.max_point_s
                    ),
                )
                .await?;
            return Ok(None);
        };
        let n = window.len() as f64;
        let mean = |f: &dyn Fn(&Reading) -> f64| window.iter().map(f).sum::<f64>() / n;
        self.window_temperature = mean_of(window.iter().map(|r| r.winding_temperature));
        // The speed over the window: the slope of the angle the encoder
        // readings add up to against time (least squares, then again
        // without the readings whose timestamps a stall threw off).
        let t0 = window.first().map_or(0, |r| r.t_ns);
        let (times, speeds): (Vec<f64>, Vec<f64>) = self
            .speeds
            .iter()
            .filter(|(t, _)| *t >= t0)
            .map(|&(t, w)| (t as f64 * 1e-9, w))
            .unzip();
        let speed = if speeds.is_empty() {
            window.last().and_then(|r| r.speed).unwrap_or(f64::NAN)
        } else {
            angle_slope(
                &times,
                &speeds,
                std::f64::consts::TAU / self.plan.encoder_counts_per_rev,
            )
        };
        let torques: Vec<f64> = window.iter().filter_map(|r| r.torque).collect();
        let point = OperatingPoint {
            segment,
            slip: (1.0 - speed / ws).clamp(0.0, 1.0),
            line_voltage: mean(&|r| r.voltage),
            line_current: mean(&|r| r.current),
            input_power: mean(&|r| r.power),
            speed,
            frequency: self.plan.frequency,
            torque: (!torques.is_empty())
                .then(|| torques.iter().sum::<f64>() / torques.len() as f64),
            winding_temperature: self.window_temperature,
        };
        Ok(Some((point, hot)))
    }

    /// Supply off for the plan's cool-down, then on again at `voltage`.
    pub async fn cool_down(&mut self, voltage: f64) -> Result<(), Halt> {
        self.vfd.set_output_enabled(false).await?;
        self.seq.command(self.ix.vfd_rec, 0.0).await?;
        self.seq
            .event(
                EventLevel::Info,
                format!("cool-down: supply off for {} s", self.plan.cooldown_s),
            )
            .await?;
        let start = self.t_ns();
        while ((self.t_ns() - start) as f64) * 1e-9 < self.plan.cooldown_s {
            self.read().await?;
        }
        self.vfd.set_output_enabled(true).await?;
        self.seq.command(self.ix.vfd_rec, voltage).await?;
        Ok(())
    }

    /// The slip sweep: one segment per supply voltage.
    pub async fn run(&mut self) -> Result<(), Halt> {
        let plan = self.plan;
        for (j, &v) in plan.voltages.iter().enumerate() {
            let k = self.first_segment + j;
            let label = format!("{v:.0} V, {} Hz", plan.frequency);
            let kind = SegmentKind::ImSlipSweep;
            self.seq
                .marker(k, kind, SegmentPhase::Start, &label)
                .await?;
            self.seq
                .segment(k, self.first_segment + plan.voltages.len(), &label);
            self.vfd.set_setpoint(v).await?;
            self.vfd.set_output_enabled(true).await?;
            self.dyno.set_output_enabled(true).await?;
            self.seq.command(self.ix.vfd_rec, v).await?;
            for &s in &plan.slips {
                if let Some((point, hot)) = self.point(k as u32, s).await? {
                    let t_ns = self.t_ns();
                    self.seq.push(Entry::OperatingPoint { t_ns, point }).await?;
                    if hot {
                        self.cool_down(v).await?;
                    }
                }
            }
            self.seq.marker(k, kind, SegmentPhase::End, &label).await?;
        }
        Ok(())
    }
}

/// Run `plan` on the rig under `rules` (the limits, the supervisor's
/// checks, the plan's heating budget: see [`ImSweepPlan::safety_rules`]
/// for a bare plan); every reading goes to `sink`, progress (segments,
/// test time) to `progress`. The stages are left in their safe state
/// however the test ends. `stops` is an operator-stop flag, or the
/// supervisor's handle when the rig is supervised (see [`StopPath`]).
#[allow(clippy::too_many_arguments)]
pub async fn run_im_sweep<'s>(
    plan: &ImSweepPlan,
    rules: &SafetyRules,
    vfd: &mut dyn PowerStage,
    dyno: &mut dyn PowerStage,
    sensors: &mut dyn SensorStream,
    sink: &mut RecordSink,
    progress: &dyn Progress,
    stops: impl Into<StopPath<'s>>,
) -> Result<Outcome, BenchError> {
    let stages = ImStages {
        vfd,
        dyno,
        dc: None,
    };
    run_im_plan(
        plan,
        None,
        rules,
        stages,
        sensors,
        sink,
        progress,
        stops.into(),
    )
    .await
}

/// The stages of an induction-machine rig as a plan drives them.
pub(super) struct ImStages<'a> {
    /// The supply.
    pub vfd: &'a mut dyn PowerStage,
    /// The dynamometer.
    pub dyno: &'a mut dyn PowerStage,
    /// The DC source of the winding-resistance test, where fitted.
    pub dc: Option<&'a mut dyn PowerStage>,
}

/// Run the slip sweep `plan`, after the standard tests `standard` when
/// given (see [`run_im_sweep`] for the rest).
#[allow(clippy::too_many_arguments)]
pub(super) async fn run_im_plan(
    plan: &ImSweepPlan,
    standard: Option<&StandardTestsPlan>,
    rules: &SafetyRules,
    stages: ImStages<'_>,
    sensors: &mut dyn SensorStream,
    sink: &mut RecordSink,
    progress: &dyn Progress,
    stops: StopPath<'_>,
) -> Result<Outcome, BenchError> {
    let ImStages { vfd, dyno, mut dc } = stages;
    let channels = sensors.channels().to_vec();
    let find = |q: &'static str| {
        channels
            .iter()
            .position(|c| c.quantity == q)
            .ok_or(BenchError::MissingChannel(q))
    };
    let n = channels.len();
    let found = (|| {
        let ix = Indices {
            voltage: find("line_voltage")?,
            current: find("line_current")?,
            power: find("input_power")?,
            torque: channels.iter().position(|c| c.quantity == "torque"),
            dc: match (standard, &dc) {
                (Some(_), Some(_)) => Some((find("dc_voltage")?, find("dc_current")?)),
                (Some(_), None) => return Err(BenchError::MissingChannel("dc_source")),
                (None, _) => None,
            },
            temperature: channels
                .iter()
                .position(|c| c.quantity == "winding_temperature"),
            vfd_rec: n + 1,
            dyno_rec: n + 2,
            dc_rec: n + 3,
            frequency_rec: n + 4,
        };
        let speed = SpeedChannel {
            encoder: find("encoder_count")?,
            speed_rec: n,
            counts_per_rev: plan.encoder_counts_per_rev,
        };
        let monitor = rules
            .monitor(&channels, Some(plan.encoder_counts_per_rev), 0.0)
            .map_err(BenchError::Safety)?;
        Ok::<_, BenchError>((ix, speed, monitor))
    })();
    let (ix, speed, monitor) = match found {
        Ok(found) => found,
        Err(e) => {
            safe_state_all(&mut all_stages(vfd, dyno, dc.as_deref_mut())).await;
            return Err(e);
        }
    };
    let seq = Sequencer::new(
        sensors,
        sink,
        progress,
        stops,
        monitor,
        speed,
        f64::INFINITY,
    );
    let mut sweep = Sweep {
        plan,
        vfd,
        dyno,
        // Each reference as the sweep's (a trait object's lifetime does
        // not shorten inside an Option by itself).
        dc: match dc {
            Some(dc) => Some(dc as &mut dyn PowerStage),
            None => None,
        },
        seq,
        ix,
        speeds: Vec::new(),
        held: Reading {
            t_ns: 0,
            voltage: f64::NAN,
            current: f64::NAN,
            power: f64::NAN,
            speed: None,
            torque: None,
            dc_voltage: f64::NAN,
            dc_current: f64::NAN,
            winding_temperature: None,
        },
        first_segment: 0,
        window_temperature: None,
        speed_disagrees: false,
    };
    let result = match standard {
        Some(tests) => sweep.run_standard(tests).await,
        None => sweep.run().await,
    };
    // A fault the plan saw itself goes to the supervisor (safe state,
    // escalation, latch).
    if let Err(Halt::Fault(reason)) = &result {
        sweep.seq.hand_over(reason).await;
    }
    // Safe state first, whatever happened: every stage at once, the
    // supply first.
    let safe = safe_state_all(&mut all_stages(
        &mut *sweep.vfd,
        &mut *sweep.dyno,
        sweep.dc.as_deref_mut(),
    ))
    .await;
    let outcome = match result {
        Ok(()) => Outcome::Completed,
        Err(Halt::Record(e)) => return Err(BenchError::Record(e)),
        Err(Halt::Fault(reason)) => {
            sweep
                .seq
                .event(
                    EventLevel::Abort,
                    format!("{reason}; supply off, dynamometer braking"),
                )
                .await?;
            Outcome::Aborted { reason }
        }
    };
    sweep.seq.sampling_summary().await?;
    for (name, r) in ["supply", "dynamometer", "DC source"].into_iter().zip(safe) {
        if let Err(e) = r {
            sweep
                .seq
                .event(EventLevel::Warn, format!("{name} safe state failed: {e}"))
                .await?;
        }
    }
    Ok(outcome)
}

/// The stages in the order their safe states go out: the supply first.
fn all_stages<'a, 'b: 'a>(
    vfd: &'a mut (dyn PowerStage + 'b),
    dyno: &'a mut (dyn PowerStage + 'b),
    dc: Option<&'a mut (dyn PowerStage + 'b)>,
) -> Vec<&'a mut dyn PowerStage> {
    let mut all: Vec<&'a mut dyn PowerStage> = vec![vfd, dyno];
    if let Some(dc) = dc {
        all.push(dc);
    }
    all
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bench::SpeedFromEncoder;

    /// Encoder speed readings of a shaft at `w` rad/s, 4096 counts a turn,
    /// polled every 5 ms; `late` readings carry a timestamp `by` s late.
    fn readings(w: f64, late: &[usize], by: f64) -> (Vec<f64>, Vec<f64>) {
        let per_rad = 4096.0 / std::f64::consts::TAU;
        let mut enc = SpeedFromEncoder::new(4096.0);
        let (mut time, mut speed) = (Vec::new(), Vec::new());
        for k in 0..101 {
            let t_true = k as f64 * 0.005;
            let count = (w * t_true * per_rad).floor();
            let t = t_true + if late.contains(&k) { by } else { 0.0 };
            if let Some(s) = enc.update((t * 1e9) as u64, count) {
                time.push(t);
                speed.push(s);
            }
        }
        (time, speed)
    }

    #[test]
    fn the_slope_averages_the_quantisation() {
        let (t, s) = readings(156.0, &[], 0.0);
        assert!((angle_slope(&t, &s, std::f64::consts::TAU / 4096.0) / 156.0 - 1.0).abs() < 2e-5);
    }

    #[test]
    fn a_stalled_reading_does_not_tilt_the_slope() {
        // Two readings stamped 3 ms late (a busy host), near the window's
        // end where they weigh most in a plain least-squares slope.
        let (t, s) = readings(156.0, &[90, 95], 0.003);
        let robust = angle_slope(&t, &s, std::f64::consts::TAU / 4096.0);
        let n = t.len();
        let mut angle = vec![0.0];
        for k in 1..n {
            angle.push(angle[k - 1] + s[k] * (t[k] - t[k - 1]));
        }
        let tm = t.iter().sum::<f64>() / n as f64;
        let am = angle.iter().sum::<f64>() / n as f64;
        let plain = t
            .iter()
            .zip(&angle)
            .map(|(x, y)| (x - tm) * (y - am))
            .sum::<f64>()
            / t.iter().map(|x| (x - tm).powi(2)).sum::<f64>();
        assert!((plain / 156.0 - 1.0).abs() > 2e-4, "{plain}");
        assert!((robust / 156.0 - 1.0).abs() < 2e-5, "{robust}");
    }
}
