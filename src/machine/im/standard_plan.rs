//! The induction machine's standard test set driven on the rig (IEEE 112
//! Method F's equivalent-circuit tests, IEC 60034-28): `im_standard_tests`
//! runs, one segment each,
//!
//! 1. `im_dc_resistance`: the supply off, the shaft held at rest, a DC
//!    source drives a few currents between two line terminals; each
//!    settled reading of DC voltage and current is averaged;
//! 2. `im_no_load`: the dynamometer brings the shaft to synchronous speed,
//!    the supply comes on at the highest voltage and the dynamometer lets
//!    the shaft go (output off: the rotor turns freely, its slip is not
//!    measured); the supply then steps down through the no-load voltages,
//!    each held until current, power and speed settle and averaged;
//! 3. `im_locked_rotor`: the dynamometer holds the shaft at rest and the
//!    supply steps up through reduced voltages until the current passes
//!    the test's ceiling (about rated current);
//! 4. when the plan asks for it ([`ReducedFrequencyTest`]), a second
//!    `im_locked_rotor` segment at a reduced supply frequency (IEEE 112:
//!    at most 25 % of rated, nearer the rotor's running slip frequency),
//!    the supply commanded there
//!    ([`motorbench_drivers::PowerStage::set_frequency`]; a supply
//!    without that command ends the test saying so) and back to rated
//!    frequency after;
//! 5. the load test: the slip sweep ([`super::ImSweepPlan`]), its segments
//!    after these.
//!
//! Where the rig reads the winding temperature, each reading carries its
//! mean over the reading's averaging window.
//!
//! Every reading goes to `/bench/standard_test` (a
//! [`StandardTestReading`]), so a replay reduces the same readings the
//! run did. The defaults come from the nameplate
//! ([`StandardTestsPlan::from_nameplate`]).

use super::sweep::mean_of;
use super::sweep::Sweep;
use crate::bench::sequencer::Halt;
use crate::bench::SettleDetector;
use crate::record::{
    DcResistanceReading, Entry, EventLevel, SegmentKind, SegmentPhase, StandardTestReading,
    SupplyReading,
};

/// The DC-resistance, no-load and locked-rotor tests of a plan.
#[derive(Debug, Clone, PartialEq)]
pub struct StandardTestsPlan {
    /// DC currents between two line terminals, A, in the order run.
    pub dc_currents: Vec<f64>,
    /// No-load line voltages, V, in the order run (highest first).
    pub no_load_voltages: Vec<f64>,
    /// Locked-rotor line voltages, V, in the order run (lowest first).
    pub locked_rotor_voltages: Vec<f64>,
    /// The locked-rotor test stops stepping up once the line current
    /// passes this, A.
    pub locked_rotor_max_current: f64,
    /// A second locked-rotor test at a reduced frequency, when asked for.
    pub reduced_frequency: Option<ReducedFrequencyTest>,
}

/// A locked-rotor test at a reduced supply frequency.
#[derive(Debug, Clone, PartialEq)]
pub struct ReducedFrequencyTest {
    /// The supply frequency, Hz.
    pub frequency: f64,
    /// Line voltages, V, in the order run (lowest first); it stops
    /// stepping up as the rated-frequency test does.
    pub voltages: Vec<f64>,
}

impl ReducedFrequencyTest {
    /// The default for a machine rated `line_voltage`: from 2 % of rated
    /// voltage up in steps of 1.5 % to 14 % (the leakage reactance falls
    /// with the frequency: a machine of 5 to 8 × rated locked-rotor current
    /// at rated frequency reaches rated current at 25 % frequency near 5
    /// to 12 % voltage).
    pub fn from_nameplate(line_voltage: f64, frequency: f64) -> ReducedFrequencyTest {
        ReducedFrequencyTest {
            frequency,
            voltages: [0.02, 0.035, 0.05, 0.065, 0.08, 0.095, 0.11, 0.125, 0.14]
                .iter()
                .map(|s| s * line_voltage)
                .collect(),
        }
    }
}

/// Segment index of the DC-resistance test; the no-load and the
/// locked-rotor tests follow, then the load test's sweeps.
pub const DC_RESISTANCE_SEGMENT: usize = 0;
/// Segment index of the no-load test.
pub const NO_LOAD_SEGMENT: usize = 1;
/// Segment index of the locked-rotor test.
pub const LOCKED_ROTOR_SEGMENT: usize = 2;
/// Segment index of the locked-rotor test at reduced frequency, when run.
pub const REDUCED_FREQUENCY_SEGMENT: usize = 3;
/// Segments before the load test's without the reduced-frequency test
/// ([`StandardTestsPlan::segments`] counts a plan's).
pub const STANDARD_SEGMENTS: usize = 3;

impl StandardTestsPlan {
    /// The defaults for a machine rated `line_voltage`, `line_current`:
    /// DC at 20, 35 and 50 % of rated current; no load from 105 % down to
    /// 30 % of rated voltage (ten voltages, four of them at or below the
    /// 60 % the friction-and-windage regression uses; the top stays clear
    /// of the supply's 110 %, the voltage limit's default); locked rotor from
    /// 5 % of rated voltage up in steps of 3 % to at most 26 %, stopping
    /// once the current passes 1.25 × rated (a machine of 5 to 8 × rated
    /// locked-rotor current reaches rated current at 12 to 20 %).
    pub fn from_nameplate(line_voltage: f64, line_current: f64) -> StandardTestsPlan {
        let of = |base: f64, shares: &[f64]| shares.iter().map(|s| s * base).collect();
        StandardTestsPlan {
            dc_currents: of(line_current, &[0.2, 0.35, 0.5]),
            no_load_voltages: of(
                line_voltage,
                &[1.05, 1.0, 0.95, 0.9, 0.85, 0.8, 0.6, 0.5, 0.4, 0.3],
            ),
            locked_rotor_voltages: of(
                line_voltage,
                &[0.05, 0.08, 0.11, 0.14, 0.17, 0.2, 0.23, 0.26],
            ),
            locked_rotor_max_current: 1.25 * line_current,
            reduced_frequency: None,
        }
    }

    /// Segments before the load test's: 3, or 4 with the locked-rotor test
    /// at reduced frequency.
    pub fn segments(&self) -> usize {
        STANDARD_SEGMENTS + usize::from(self.reduced_frequency.is_some())
    }

    /// The number of readings each test takes at most (for the plan's
    /// duration), in segment order: DC, no load (and its run-up), locked
    /// rotor, and the reduced-frequency locked rotor when run.
    pub fn points(&self) -> Vec<usize> {
        let mut points = vec![
            self.dc_currents.len(),
            self.no_load_voltages.len() + 1,
            self.locked_rotor_voltages.len(),
        ];
        if let Some(r) = &self.reduced_frequency {
            points.push(r.voltages.len());
        }
        points
    }

    /// The plan for a person, one line.
    pub fn summary(&self) -> String {
        let range = |v: &[f64]| {
            let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            format!("{lo:.1}…{hi:.1}")
        };
        let reduced = match &self.reduced_frequency {
            Some(r) => format!(
                "; im_locked_rotor at {} Hz up to {} voltages {} V",
                r.frequency,
                r.voltages.len(),
                range(&r.voltages)
            ),
            None => String::new(),
        };
        format!(
            "im_dc_resistance {} currents {} A; im_no_load {} voltages {} V; im_locked_rotor up to {} voltages {} V (to {:.1} A){reduced}",
            self.dc_currents.len(),
            range(&self.dc_currents),
            self.no_load_voltages.len(),
            range(&self.no_load_voltages),
            self.locked_rotor_voltages.len(),
            range(&self.locked_rotor_voltages),
            self.locked_rotor_max_current
        )
    }
}

impl Sweep<'_> {
    /// The standard tests, then the slip sweep.
    pub(super) async fn run_standard(&mut self, tests: &StandardTestsPlan) -> Result<(), Halt> {
        let total = tests.segments() + self.plan.voltages.len();
        self.dc_resistance(tests, total).await?;
        self.no_load(tests, total).await?;
        let rated = self.plan.frequency;
        let at_rated = LockedRotor {
            index: LOCKED_ROTOR_SEGMENT,
            frequency: rated,
            voltages: &tests.locked_rotor_voltages,
        };
        self.locked_rotor(tests, total, at_rated).await?;
        if let Some(r) = &tests.reduced_frequency {
            self.supply_frequency(r.frequency).await?;
            let reduced = LockedRotor {
                index: REDUCED_FREQUENCY_SEGMENT,
                frequency: r.frequency,
                voltages: &r.voltages,
            };
            self.locked_rotor(tests, total, reduced).await?;
            self.supply_frequency(rated).await?;
        }
        self.first_segment = tests.segments();
        self.run().await
    }

    /// Command the supply's frequency once its output is off (the line
    /// voltage below 1 % of the plan's highest: a frequency step on a live
    /// winding at its voltage drives a current the test did not ask for),
    /// and record it; a supply without that command ends the test saying
    /// so.
    async fn supply_frequency(&mut self, hz: f64) -> Result<(), Halt> {
        let off = 0.01 * self.plan.voltages.iter().copied().fold(0.0, f64::max);
        let start = self.t_ns();
        while self.read().await?.voltage.abs() > off {
            if (self.t_ns() - start) as f64 * 1e-9 > self.plan.max_point_s {
                return Err(Halt::Fault(format!(
                    "the supply's output did not come off within {} s: its frequency is not \
                     changed on a live winding",
                    self.plan.max_point_s
                )));
            }
        }
        if let Err(e) = self.vfd.set_frequency(hz).await {
            return Err(Halt::Fault(format!(
                "the locked-rotor test at reduced frequency needs the supply at {hz} Hz: {e}"
            )));
        }
        self.seq.command(self.ix.frequency_rec, hz).await?;
        Ok(())
    }

    /// Start segment `index` of `kind`.
    async fn begin(
        &mut self,
        index: usize,
        total: usize,
        kind: SegmentKind,
        label: &str,
    ) -> Result<(), Halt> {
        self.seq
            .marker(index, kind, SegmentPhase::Start, label)
            .await?;
        self.seq.segment(index, total, label);
        Ok(())
    }

    /// End segment `index` of `kind`.
    async fn end(&mut self, index: usize, kind: SegmentKind, label: &str) -> Result<(), Halt> {
        self.seq
            .marker(index, kind, SegmentPhase::End, label)
            .await?;
        Ok(())
    }

    /// Set the supply to `volts` (on) or off (`None`), and record it.
    async fn supply(&mut self, volts: Option<f64>) -> Result<(), Halt> {
        match volts {
            Some(v) => {
                self.vfd.set_setpoint(v).await?;
                self.vfd.set_output_enabled(true).await?;
            }
            None => self.vfd.set_output_enabled(false).await?,
        }
        self.seq
            .command(self.ix.vfd_rec, volts.unwrap_or(0.0))
            .await?;
        Ok(())
    }

    /// Hold the shaft at `speed` rad/s with the dynamometer, and record it.
    async fn hold_shaft(&mut self, speed: f64) -> Result<(), Halt> {
        self.dyno.set_setpoint(speed).await?;
        self.dyno.set_output_enabled(true).await?;
        self.seq.command(self.ix.dyno_rec, speed).await?;
        Ok(())
    }

    /// Drive `amperes` from the DC source (on), or disconnect it (`None`),
    /// and record it.
    async fn dc_source(&mut self, amperes: Option<f64>) -> Result<(), Halt> {
        let Some(dc) = self.dc.as_deref_mut() else {
            return Err(Halt::Fault(
                "the rig has no DC source for the winding-resistance test".into(),
            ));
        };
        match amperes {
            Some(a) => {
                dc.set_setpoint(a).await?;
                dc.set_output_enabled(true).await?;
            }
            None => dc.safe_state().await?,
        }
        self.seq
            .command(self.ix.dc_rec, amperes.unwrap_or(0.0))
            .await?;
        Ok(())
    }

    /// Record one reading (a reading with a non-finite value, which JSON
    /// cannot carry, becomes a warning instead).
    async fn reading(&mut self, reading: StandardTestReading) -> Result<(), Halt> {
        if let Some((field, v)) = reading.non_finite_field() {
            self.seq
                .event(
                    EventLevel::Warn,
                    format!("standard-test reading with {field} = {v} not recorded"),
                )
                .await?;
            return Ok(());
        }
        let t_ns = self.t_ns();
        self.seq.push(Entry::StandardTest { t_ns, reading }).await?;
        Ok(())
    }

    /// `im_dc_resistance`: the supply off, the shaft at rest, each DC
    /// current held until voltage and current settle, then averaged.
    async fn dc_resistance(&mut self, tests: &StandardTestsPlan, total: usize) -> Result<(), Halt> {
        let (index, kind) = (DC_RESISTANCE_SEGMENT, SegmentKind::ImDcResistance);
        let label = format!("DC resistance, {} currents", tests.dc_currents.len());
        self.begin(index, total, kind, &label).await?;
        self.supply(None).await?;
        self.hold_shaft(0.0).await?;
        for &amperes in &tests.dc_currents {
            self.dc_source(Some(amperes)).await?;
            if let Some(r) = self.dc_steady(index as u32, amperes).await? {
                self.reading(StandardTestReading::ImDcResistance(r)).await?;
            }
        }
        self.dc_source(None).await?;
        self.end(index, kind, &label).await
    }

    /// Wait until the DC source's voltage and current settle, then
    /// average them; `None` (with a warning) when they do not in time.
    async fn dc_steady(
        &mut self,
        segment: u32,
        amperes: f64,
    ) -> Result<Option<DcResistanceReading>, Halt> {
        let Some((_, current)) = self.ix.dc else {
            return Err(Halt::Fault(
                "the rig reads no DC voltage and current".into(),
            ));
        };
        let plan = self.plan;
        let mut detector = SettleDetector::new(plan.settle_window, plan.settle_tolerance, 2);
        let start = self.t_ns();
        loop {
            let r = self.read_on(current).await?;
            let finite = r.dc_voltage.is_finite() && r.dc_current.is_finite();
            if finite && detector.push(&[r.dc_voltage, r.dc_current]) {
                break;
            }
            if (self.t_ns() - start) as f64 * 1e-9 > plan.max_point_s {
                self.seq
                    .event(
                        EventLevel::Warn,
                        format!(
                            "DC {amperes:.3} A: not settled within {} s; reading skipped",
                            plan.max_point_s
                        ),
                    )
                    .await?;
                return Ok(None);
            }
        }
        let (mut v, mut i, mut temperatures) = (0.0, 0.0, Vec::new());
        for _ in 0..plan.average_samples {
            let r = self.read_on(current).await?;
            v += r.dc_voltage;
            i += r.dc_current;
            temperatures.push(r.winding_temperature);
        }
        let n = plan.average_samples as f64;
        Ok(Some(DcResistanceReading {
            segment,
            dc_voltage: v / n,
            dc_current: i / n,
            winding_temperature: mean_of(temperatures.into_iter()),
        }))
    }

    /// A steady reading on the supply at `frequency`, for a no-load or
    /// locked-rotor test.
    async fn supply_reading(
        &mut self,
        segment: u32,
        frequency: f64,
        what: &str,
    ) -> Result<Option<(SupplyReading, bool)>, Halt> {
        let steady = self.steady(segment, what).await?;
        let winding_temperature = self.window_temperature;
        Ok(steady.map(|(p, hot)| {
            let reading = SupplyReading {
                segment,
                line_voltage: p.line_voltage,
                line_current: p.line_current,
                input_power: p.input_power,
                frequency,
                winding_temperature,
            };
            (reading, hot)
        }))
    }

    /// Read until the shaft turns within 1 % of `speed` rad/s; a fault
    /// when it does not within the plan's settle timeout.
    async fn reach_speed(&mut self, speed: f64) -> Result<(), Halt> {
        let start = self.t_ns();
        loop {
            let r = self.read().await?;
            if r.speed.is_some_and(|w| (w - speed).abs() <= 0.01 * speed) {
                return Ok(());
            }
            if (self.t_ns() - start) as f64 * 1e-9 > self.plan.max_point_s {
                return Err(Halt::Fault(format!(
                    "no-load run-up: the dynamometer did not bring the shaft to {speed:.2} rad/s \
                     within {} s",
                    self.plan.max_point_s
                )));
            }
        }
    }

    /// `im_no_load`: run up with the dynamometer, let the shaft go, step
    /// the supply down through the voltages.
    async fn no_load(&mut self, tests: &StandardTestsPlan, total: usize) -> Result<(), Halt> {
        let (index, kind) = (NO_LOAD_SEGMENT, SegmentKind::ImNoLoad);
        let label = format!("no load, {} voltages", tests.no_load_voltages.len());
        self.begin(index, total, kind, &label).await?;
        let Some(&first) = tests.no_load_voltages.first() else {
            return self.end(index, kind, &label).await;
        };
        // The dynamometer brings the shaft up to synchronous speed, the
        // supply comes on there (no direct-on-line start), then the
        // dynamometer lets it go.
        let ws = self.plan.synchronous_speed();
        self.hold_shaft(ws).await?;
        self.reach_speed(ws).await?;
        self.supply(Some(first)).await?;
        self.steady(index as u32, "no-load run-up").await?;
        self.dyno.set_output_enabled(false).await?;
        self.seq
            .event(
                EventLevel::Info,
                "no load: dynamometer off, the rotor turns freely".into(),
            )
            .await?;
        for &volts in &tests.no_load_voltages {
            self.supply(Some(volts)).await?;
            let what = format!("no load at {volts:.1} V");
            let frequency = self.plan.frequency;
            if let Some((r, _)) = self.supply_reading(index as u32, frequency, &what).await? {
                self.reading(StandardTestReading::ImNoLoad(r)).await?;
            }
        }
        self.supply(None).await?;
        self.end(index, kind, &label).await
    }

    /// `im_locked_rotor`: the shaft held at rest, the supply stepped up
    /// through `test`'s voltages at its frequency until the current passes
    /// the test's ceiling.
    async fn locked_rotor(
        &mut self,
        tests: &StandardTestsPlan,
        total: usize,
        test: LockedRotor<'_>,
    ) -> Result<(), Halt> {
        let (index, kind) = (test.index, SegmentKind::ImLockedRotor);
        let label = format!(
            "locked rotor at {} Hz, up to {} voltages",
            test.frequency,
            test.voltages.len()
        );
        self.begin(index, total, kind, &label).await?;
        self.hold_shaft(0.0).await?;
        for &volts in test.voltages {
            self.supply(Some(volts)).await?;
            let what = format!("locked rotor at {volts:.1} V, {} Hz", test.frequency);
            let reading = self
                .supply_reading(index as u32, test.frequency, &what)
                .await?;
            let Some((r, hot)) = reading else {
                continue;
            };
            self.reading(StandardTestReading::ImLockedRotor(r)).await?;
            if hot || r.line_current > tests.locked_rotor_max_current {
                self.seq
                    .event(
                        EventLevel::Info,
                        format!(
                            "locked rotor: {:.2} A at {volts:.1} V passes the test's {:.2} A: no higher voltage",
                            r.line_current, tests.locked_rotor_max_current
                        ),
                    )
                    .await?;
                break;
            }
        }
        self.supply(None).await?;
        self.end(index, kind, &label).await
    }
}

/// One locked-rotor segment: its index, frequency and voltages.
struct LockedRotor<'a> {
    index: usize,
    frequency: f64,
    voltages: &'a [f64],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_follow_the_nameplate() {
        let p = StandardTestsPlan::from_nameplate(400.0, 8.0);
        assert_eq!(p.dc_currents.len(), 3);
        assert!((p.dc_currents[2] - 4.0).abs() < 1e-12);
        assert!((p.no_load_voltages[0] - 420.0).abs() < 1e-9);
        // At least three no-load voltages at or below 60 % of rated, for
        // the friction-and-windage regression.
        let low = p.no_load_voltages.iter().filter(|v| **v <= 240.0).count();
        assert!(low >= 3, "{low}");
        assert!(p.locked_rotor_voltages.windows(2).all(|w| w[0] < w[1]));
        assert_eq!(p.locked_rotor_max_current, 10.0);
        assert_eq!(p.points(), [3, 11, 8]);
        assert_eq!(p.segments(), 3);
        let reduced = StandardTestsPlan {
            reduced_frequency: Some(ReducedFrequencyTest::from_nameplate(400.0, 12.5)),
            ..p.clone()
        };
        assert_eq!(reduced.points(), [3, 11, 8, 9]);
        assert_eq!(reduced.segments(), 4);
        assert!(
            reduced
                .summary()
                .contains("im_locked_rotor at 12.5 Hz up to 9 voltages 8.0…56.0 V"),
            "{}",
            reduced.summary()
        );
        assert!(
            p.summary().contains("im_no_load 10 voltages 120.0…420.0 V"),
            "{}",
            p.summary()
        );
    }
}
