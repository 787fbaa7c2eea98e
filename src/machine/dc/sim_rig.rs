//! The simulated rig: a DC motor behind a simulated armature supply and
//! simulated sensors, implementing the driver traits.
//!
//! The supply ([`SimPowerStage`]) and the sensors ([`SimSensors`]) share one
//! plant. Each [`SensorStream::next_batch`] advances the plant by one
//! sample period on a virtual clock, so a test runs as fast as the CPU
//! allows; with `realtime` it also waits for the wall clock to catch up.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use async_trait::async_trait;
use motorbench_drivers::{
    ChannelInfo, DriverError, PowerStage, Sample, SampleBatch, SensorStream, StageCapabilities,
};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

use crate::config::SimulatedRig;
use crate::machine::sim_parts::lock_plant;
use crate::model::{DcMotor, DcState, ParamError, Terminal};
use crate::rig::Pacing;

const STAGE_ID: &str = "sim-supply";
const SENSORS_ID: &str = "sim-daq";

/// Channel indices of [`SimSensors`].
pub mod channel {
    /// Armature voltage at the motor terminals, V.
    pub const VOLTAGE: usize = 0;
    /// Armature current, A.
    pub const CURRENT: usize = 1;
    /// Encoder count (quadrature, 4 per line).
    pub const ENCODER: usize = 2;
}

#[derive(Debug)]
struct Plant {
    motor: DcMotor,
    state: DcState,
    setpoint: f64,
    output: f64,
    enabled: bool,
    current_limit: f64,
    current_rating: f64,
    max_voltage: f64,
    slew_per_step: f64,
    step: u64,
    /// Heartbeat timeout, in plant steps.
    heartbeat_timeout_steps: u64,
    /// Step of the last heartbeat; `None` until armed.
    last_heartbeat: Option<u64>,
    /// The heartbeat timed out and the supply made itself safe; the output
    /// stays off until the next heartbeat.
    heartbeat_lost: bool,
}

impl Plant {
    /// Advance one sample period; the terminal voltage over the period.
    fn advance(&mut self) -> f64 {
        if let Some(last) = self.last_heartbeat {
            if self.step - last > self.heartbeat_timeout_steps {
                // Nobody petted the heartbeat: safe state, by itself.
                self.setpoint = 0.0;
                self.output = 0.0;
                self.enabled = false;
                self.heartbeat_lost = true;
                self.last_heartbeat = None;
            }
        }
        let target = if self.enabled { self.setpoint } else { 0.0 };
        self.output += (target - self.output).clamp(-self.slew_per_step, self.slew_per_step);
        let mut terminal = self.output;
        self.state = if self.enabled {
            let mut next = self.motor.step(&self.state, Terminal::Driven(self.output));
            if next.current.abs() > self.current_limit {
                // Constant-current mode: the supply lowers its voltage to
                // hold the limit (quasi-static: the limit current's
                // resistive drop plus the back-EMF), and that lower voltage
                // is what the motor's terminals (and the voltmeter) see.
                let p = self.motor.params();
                terminal =
                    p.ra * self.current_limit.copysign(next.current) + p.k * self.state.speed;
                next = self.motor.step(&self.state, Terminal::Driven(terminal));
            }
            next
        } else {
            self.motor.step(&self.state, Terminal::Open)
        };
        self.step += 1;
        if self.enabled {
            terminal
        } else {
            self.motor.params().k * self.state.speed
        }
    }
}

/// The simulated armature supply.
#[derive(Debug, Clone)]
pub struct SimPowerStage {
    plant: Arc<Mutex<Plant>>,
}

/// The simulated sensors: voltage and current ADCs and an encoder.
#[derive(Debug)]
pub struct SimSensors {
    plant: Arc<Mutex<Plant>>,
    channels: Vec<ChannelInfo>,
    period_ns: f64,
    rng: StdRng,
    voltage: Adc,
    current: Adc,
    counts_per_rad: f64,
    pacing: Pacing,
}

#[derive(Debug, Clone, Copy)]
struct Adc {
    noise: Option<Normal<f64>>,
    lsb: f64,
    full_scale: f64,
}

impl Adc {
    fn new(noise: f64, full_scale: f64, bits: u32) -> Adc {
        let noise =
            (noise > 0.0).then(|| Normal::new(0.0, noise).expect("noise checked ≥ 0 by config"));
        Adc {
            noise,
            lsb: 2.0 * full_scale / f64::from(1u32 << bits),
            full_scale,
        }
    }

    fn read(&self, value: f64, rng: &mut StdRng) -> f64 {
        let noisy = value + self.noise.map_or(0.0, |n| n.sample(rng));
        (noisy.clamp(-self.full_scale, self.full_scale) / self.lsb).round() * self.lsb
    }
}

/// Build the simulated rig from its configuration; both halves share one
/// plant, at rest with the output disabled.
pub fn sim_rig(
    cfg: &SimulatedRig,
    sample_rate_hz: f64,
    realtime: bool,
) -> Result<(SimPowerStage, SimSensors), ParamError> {
    let dt = 1.0 / sample_rate_hz;
    let plant = Arc::new(Mutex::new(Plant {
        motor: DcMotor::new(cfg.motor, dt)?,
        state: DcState::default(),
        setpoint: 0.0,
        output: 0.0,
        enabled: false,
        current_limit: cfg.power_stage.current_limit,
        current_rating: cfg.power_stage.current_limit,
        max_voltage: cfg.power_stage.max_voltage,
        slew_per_step: cfg.power_stage.slew * dt,
        step: 0,
        heartbeat_timeout_steps: (cfg.power_stage.heartbeat_timeout * sample_rate_hz).ceil() as u64,
        last_heartbeat: None,
        heartbeat_lost: false,
    }));
    let s = &cfg.sensors;
    let info = |quantity: &str, unit: &str| ChannelInfo {
        quantity: quantity.into(),
        unit: unit.into(),
        source: SENSORS_ID.into(),
        rate_hz: sample_rate_hz,
    };
    let sensors = SimSensors {
        plant: plant.clone(),
        channels: vec![
            info("armature_voltage", "V"),
            info("armature_current", "A"),
            info("encoder_count", "count"),
        ],
        period_ns: 1e9 / sample_rate_hz,
        rng: StdRng::seed_from_u64(s.seed),
        voltage: Adc::new(s.voltage_noise, s.voltage_full_scale, s.voltage_bits),
        current: Adc::new(s.current_noise, s.current_full_scale, s.current_bits),
        counts_per_rad: f64::from(s.encoder_lines) * 4.0 / std::f64::consts::TAU,
        pacing: if realtime {
            Pacing::wall_from_now()
        } else {
            Pacing::Virtual
        },
    };
    Ok((SimPowerStage { plant }, sensors))
}

impl SimPowerStage {
    /// True when the output is enabled (for tests and diagnostics).
    pub fn output_enabled(&self) -> bool {
        lock_plant(&self.plant).enabled
    }

    /// The voltage set point (for tests and diagnostics).
    pub fn setpoint(&self) -> f64 {
        lock_plant(&self.plant).setpoint
    }

    /// True when the heartbeat timed out and the supply made itself safe
    /// (cleared by the next heartbeat).
    pub fn heartbeat_lost(&self) -> bool {
        lock_plant(&self.plant).heartbeat_lost
    }
}

#[async_trait]
impl PowerStage for SimPowerStage {
    fn id(&self) -> &str {
        STAGE_ID
    }

    fn capabilities(&self) -> StageCapabilities {
        StageCapabilities {
            current_limit: true,
            max_setpoint: lock_plant(&self.plant).max_voltage,
        }
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        if !value.is_finite() || value.abs() > p.max_voltage {
            return Err(DriverError::Device {
                device: STAGE_ID.into(),
                reason: format!("set point {value} V is outside ±{} V", p.max_voltage),
            });
        }
        p.setpoint = value;
        Ok(())
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        if enabled && p.heartbeat_lost {
            return Err(DriverError::Device {
                device: STAGE_ID.into(),
                reason: "heartbeat lost: the output stays off until the next heartbeat".into(),
            });
        }
        if !enabled {
            p.output = 0.0;
        }
        p.enabled = enabled;
        Ok(())
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        p.setpoint = 0.0;
        p.output = 0.0;
        p.enabled = false;
        Ok(())
    }

    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        Ok(Some(lock_plant(&self.plant).enabled))
    }

    async fn set_current_limit(&mut self, amperes: f64) -> Result<(), DriverError> {
        if !(amperes.is_finite() && amperes > 0.0) {
            return Err(DriverError::Device {
                device: STAGE_ID.into(),
                reason: format!("current limit {amperes} A"),
            });
        }
        let mut p = lock_plant(&self.plant);
        // The supply cannot limit above its own rating.
        p.current_limit = amperes.min(p.current_rating);
        Ok(())
    }

    fn heartbeat_timeout(&self) -> Option<Duration> {
        let p = lock_plant(&self.plant);
        let dt = p.motor.dt();
        Some(Duration::from_secs_f64(
            p.heartbeat_timeout_steps as f64 * dt,
        ))
    }

    /// Arms the heartbeat (in plant time: the supply counts sample
    /// periods) and clears a lost heartbeat.
    async fn heartbeat(&mut self) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        p.last_heartbeat = Some(p.step);
        p.heartbeat_lost = false;
        Ok(())
    }
}

#[async_trait]
impl SensorStream for SimSensors {
    fn id(&self) -> &str {
        SENSORS_ID
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        let batch = self.sample();
        let step = (batch.t_ns as f64 / self.period_ns).round() as u64;
        self.pacing.wait(batch.t_ns, step).await;
        Ok(batch)
    }

    fn virtual_clock(&self) -> bool {
        self.pacing.is_virtual()
    }
}

impl SimSensors {
    /// Advance the plant by one sample period and read the sensors (what
    /// [`SensorStream::next_batch`] does, without any pacing): for
    /// simulated devices that run the plant on their own clock.
    pub fn sample(&mut self) -> SampleBatch {
        let (step, terminal_voltage, state) = {
            let mut p = lock_plant(&self.plant);
            let u = p.advance();
            (p.step, u, p.state)
        };
        let t_ns = (step as f64 * self.period_ns).round() as u64;
        let samples = vec![
            Sample {
                channel: channel::VOLTAGE,
                value: self.voltage.read(terminal_voltage, &mut self.rng),
            },
            Sample {
                channel: channel::CURRENT,
                value: self.current.read(state.current, &mut self.rng),
            },
            Sample {
                channel: channel::ENCODER,
                value: (state.angle * self.counts_per_rad).floor(),
            },
        ];
        SampleBatch { t_ns, samples }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Config;

    fn rig() -> (SimPowerStage, SimSensors) {
        let sim = Config::embedded_default()
            .backend
            .simulated()
            .cloned()
            .unwrap();
        sim_rig(&sim, 2000.0, false).unwrap()
    }

    #[tokio::test(start_paused = true)]
    async fn realtime_mode_paces_batches_at_the_wall_clock() {
        let sim = Config::embedded_default()
            .backend
            .simulated()
            .cloned()
            .unwrap();
        let (_, mut fast) = sim_rig(&sim, 2000.0, false).unwrap();
        let start = tokio::time::Instant::now();
        for _ in 0..2000 {
            fast.next_batch().await.unwrap();
        }
        assert_eq!(start.elapsed(), Duration::ZERO, "virtual clock: no waiting");
        let (_, mut paced) = sim_rig(&sim, 2000.0, true).unwrap();
        let start = tokio::time::Instant::now();
        for _ in 0..2000 {
            paced.next_batch().await.unwrap();
        }
        // The paused clock advances exactly to each sample's deadline.
        assert_eq!(start.elapsed(), Duration::from_secs(1));
    }

    #[tokio::test]
    async fn disabled_output_leaves_the_motor_at_rest() {
        let (_, mut sensors) = rig();
        for _ in 0..100 {
            let b = sensors.next_batch().await.unwrap();
            assert_eq!(b.samples[channel::ENCODER].value, 0.0);
            assert!(b.samples[channel::CURRENT].value.abs() < 0.02);
        }
    }

    #[tokio::test]
    async fn driven_motor_reaches_the_seed_steady_state_and_clock_is_exact() {
        let (mut stage, mut sensors) = rig();
        stage.set_setpoint(60.0).await.unwrap();
        stage.set_output_enabled(true).await.unwrap();
        let mut last = None;
        let mut current = 0.0;
        for k in 1..=4000u64 {
            let b = sensors.next_batch().await.unwrap();
            assert_eq!(b.t_ns, k * 500_000);
            if k > 2000 {
                current += b.samples[channel::CURRENT].value / 2000.0;
            }
            last = Some(b);
        }
        let b = last.unwrap();
        assert!((b.samples[channel::VOLTAGE].value - 60.0).abs() < 0.5);
        assert!((current - 0.113).abs() < 1e-3, "mean current {current}");
    }

    #[tokio::test]
    async fn setpoint_beyond_the_supply_is_refused_and_safe_state_disables() {
        let (mut stage, _) = rig();
        let err = stage.set_setpoint(1000.0).await.unwrap_err();
        assert!(matches!(err, DriverError::Device { .. }));
        stage.set_setpoint(100.0).await.unwrap();
        stage.set_output_enabled(true).await.unwrap();
        stage.safe_state().await.unwrap();
        assert!(!stage.output_enabled());
        assert_eq!(stage.setpoint(), 0.0);
    }

    #[tokio::test]
    async fn unpetted_heartbeat_makes_the_supply_safe_by_itself() {
        let (mut stage, mut sensors) = rig();
        // 0.25 s at 2 kHz: 500 steps.
        let timeout = stage.heartbeat_timeout().unwrap().as_secs_f64();
        assert!((timeout - 0.25).abs() < 1e-9, "{timeout}");
        stage.set_setpoint(60.0).await.unwrap();
        stage.set_output_enabled(true).await.unwrap();
        // Not armed yet: no heartbeat needed (the CLI's `run` never pets).
        for _ in 0..2000 {
            sensors.next_batch().await.unwrap();
        }
        assert!(stage.output_enabled());
        // Armed and petted every 100 steps: stays on.
        for k in 0..2000 {
            if k % 100 == 0 {
                stage.heartbeat().await.unwrap();
            }
            sensors.next_batch().await.unwrap();
        }
        assert!(stage.output_enabled() && !stage.heartbeat_lost());
        // Petting stops (a dead controller): safe after the timeout.
        let mut on = 0;
        for _ in 0..600 {
            let b = sensors.next_batch().await.unwrap();
            if stage.output_enabled() {
                on += 1;
            } else {
                assert!(b.samples[channel::CURRENT].value.abs() < 0.02);
            }
        }
        assert!(!stage.output_enabled() && stage.heartbeat_lost());
        assert_eq!(stage.setpoint(), 0.0);
        // Last pet at step 3900 (k = 1900), 99 steps before petting
        // stopped; the supply trips on the first step more than 500 after it.
        assert_eq!(on, 500 - 99);
        // It will not switch on again until a controller pets it.
        assert!(stage.set_output_enabled(true).await.is_err());
        stage.heartbeat().await.unwrap();
        stage.set_output_enabled(true).await.unwrap();
    }

    #[tokio::test]
    async fn current_limit_holds_the_inrush() {
        let (mut stage, mut sensors) = rig();
        stage.set_current_limit(0.5).await.unwrap();
        stage.set_setpoint(248.0).await.unwrap();
        stage.set_output_enabled(true).await.unwrap();
        for k in 0..2000 {
            let b = sensors.next_batch().await.unwrap();
            // Limit plus ADC noise and one step of overshoot.
            assert!(b.samples[channel::CURRENT].value < 0.56, "{:?}", b.samples);
            if (100..400).contains(&k) {
                // Held at 0.5 A while the shaft is slow, the supply's
                // voltage (what the voltmeter reads) is far below 248 V:
                // 0.5 A · 30.9 Ω plus a back-EMF below 1.323 · 35 V.
                let u = b.samples[channel::VOLTAGE].value;
                assert!(u < 70.0, "step {k}: the voltmeter reads {u} V");
            }
        }
    }
}
