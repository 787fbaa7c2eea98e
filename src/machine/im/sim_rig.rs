//! The simulated slip-sweep rig: an induction machine on a fixed-voltage,
//! fixed-frequency supply (a VFD, [`SimVfd`]) whose shaft a dynamometer
//! holds at a speed set point ([`SimDyno`]), read by [`SimImSensors`]: line
//! voltage, line current, three-phase input power, an encoder and,
//! optionally, a shaft-torque sensor, each with Gaussian noise. For the
//! standard tests the rig may also have a DC source ([`SimDcSource`],
//! from [`SimVfd::dc_source`]) that drives a current between two line
//! terminals with the supply off, read on `dc_voltage` and `dc_current`
//! (a current source up to its compliance voltage), and a winding
//! thermometer ([`SimImRigConfig::winding_sensor`], read on
//! `winding_temperature`, °C). The supply's frequency may be commanded
//! below its rated one ([`PowerStage::set_frequency`]: a locked-rotor test
//! at reduced frequency): every reactance of the circuit scales with it.
//!
//! The electrical side is quasi-static (the steady-state circuit at the
//! instantaneous slip: electrical transients last milliseconds, the
//! mechanical ones tenths of seconds); the dynamometer's speed follows its
//! set point with a first-order lag and a rate limit; the supply slews to
//! its voltage. Uncoupled from the dynamometer (its output off) the rotor
//! runs where its torque meets the friction and windage on its shaft
//! (a loss `∝ ω²` given at synchronous speed, [`free_rotor_slip`]), which
//! the torque sensor, between the machine and the dynamometer, does not
//! see; the core loss is the circuit's `Rfe`. A first-order thermal model
//! heats the winding with the
//! machine's losses and raises `Rs` with the copper's temperature
//! coefficient (the `thermal_drift` effect; zero heating turns it off).
//! Each [`SensorStream::next_batch`] advances the plant by one sample
//! period on a virtual clock, as fast as the CPU allows, or paced at the
//! wall clock ([`SimImSensors::paced`]) as a real rig would be.

use std::sync::{Arc, Mutex};

use async_trait::async_trait;
use motorbench_drivers::{
    ChannelInfo, DriverError, PowerStage, Sample, SampleBatch, SensorStream, StageCapabilities,
};
use rand::rngs::StdRng;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal, StandardNormal};

use crate::machine::sim_parts::lock_plant;
use crate::model::{
    at_frequency, free_rotor_slip, terminal_resistance, ImCircuit, ImCircuitError, ImSupply,
};
use crate::rig::{check_frequency, check_setpoint, Pacing};

const VFD_ID: &str = "sim-vfd";
const DYNO_ID: &str = "sim-dyno";
const SENSORS_ID: &str = "sim-im-daq";
const DC_SOURCE_ID: &str = "sim-dc-source";

/// Copper's temperature coefficient of resistance at 20 °C, 1/K.
pub const COPPER_ALPHA: f64 = 0.00393;

/// Settings of the simulated rig.
#[derive(Debug, Clone, PartialEq)]
pub struct SimImRigConfig {
    /// The machine, Ω per phase at 20 °C (Rs) and at the supply frequency.
    pub circuit: ImCircuit,
    /// Rated supply: line voltage (the VFD's maximum), frequency,
    /// connection, pole pairs.
    pub supply: ImSupply,
    /// Sample rate of the sensors, Hz.
    pub sample_rate_hz: f64,
    /// Time constant of the dynamometer's speed loop, s.
    pub dyno_time_constant_s: f64,
    /// Largest speed change rate of the dynamometer, rad/s².
    pub dyno_max_accel: f64,
    /// Supply voltage slew, V/s.
    pub vfd_slew_v_per_s: f64,
    /// σ of each sensor reading as a fraction of it.
    pub noise_relative: f64,
    /// Encoder lines per turn (4 counts per line).
    pub encoder_lines: u32,
    /// Whether a shaft-torque sensor is fitted.
    pub torque_sensor: bool,
    /// Winding temperature rise per watt of loss in steady state, K/W
    /// (0: no heating).
    pub thermal_resistance_k_per_w: f64,
    /// Thermal time constant of the winding, s.
    pub thermal_time_constant_s: f64,
    /// Ambient (and initial winding) temperature, °C.
    pub ambient_c: f64,
    /// Seed of the noise.
    pub seed: u64,
    /// Friction and windage at synchronous speed, W (`∝ ω²`; 0: none).
    pub friction_windage_w: f64,
    /// The DC source for the winding-resistance test, when fitted: its
    /// largest current, A.
    pub dc_source_max_current: Option<f64>,
    /// Whether a winding thermometer is fitted (channel
    /// `winding_temperature`, °C; σ 0.1 K when the sensors are noisy).
    pub winding_sensor: bool,
}

impl SimImRigConfig {
    /// Defaults for `circuit` on `supply`: 500 Hz, a dynamometer with
    /// 50 ms lag and 200 rad/s², 0.5 % sensor noise, a 1024-line encoder,
    /// a torque sensor, a winding heating by 0.02 K/W with 60 s, no
    /// friction and windage, no DC source.
    pub fn new(circuit: ImCircuit, supply: ImSupply) -> SimImRigConfig {
        SimImRigConfig {
            circuit,
            supply,
            sample_rate_hz: 500.0,
            dyno_time_constant_s: 0.05,
            dyno_max_accel: 200.0,
            vfd_slew_v_per_s: 2000.0,
            noise_relative: 0.005,
            encoder_lines: 1024,
            torque_sensor: true,
            thermal_resistance_k_per_w: 0.02,
            thermal_time_constant_s: 60.0,
            ambient_c: 20.0,
            seed: 1,
            friction_windage_w: 0.0,
            dc_source_max_current: None,
            winding_sensor: false,
        }
    }
}

/// Channel indices of [`SimImSensors`].
pub mod channel {
    /// RMS line-to-line voltage, V.
    pub const LINE_VOLTAGE: usize = 0;
    /// RMS line current, A.
    pub const LINE_CURRENT: usize = 1;
    /// Three-phase input power, W.
    pub const INPUT_POWER: usize = 2;
    /// Encoder count (quadrature, 4 per line).
    pub const ENCODER: usize = 3;
    /// Shaft torque, N·m (when fitted).
    pub const TORQUE: usize = 4;
}

/// σ of the winding thermometer's reading when the sensors are noisy, K.
const WINDING_SENSOR_SIGMA_K: f64 = 0.1;

#[derive(Debug)]
struct Plant {
    cfg: SimImRigConfig,
    dt: f64,
    vfd_setpoint: f64,
    vfd_output: f64,
    vfd_enabled: bool,
    dyno_setpoint: f64,
    dyno_enabled: bool,
    dc_setpoint: f64,
    dc_enabled: bool,
    /// The DC source's compliance voltage, V (its current falls short
    /// of the set point where the winding would need more).
    dc_compliance: f64,
    /// The supply's output frequency now, Hz.
    frequency: f64,
    speed: f64,
    angle: f64,
    winding_c: f64,
    step: u64,
}

/// What the plant shows at one instant.
#[derive(Debug, Clone, Copy)]
struct Snapshot {
    line_voltage: f64,
    line_current: f64,
    input_power: f64,
    torque: f64,
    angle: f64,
    dc_voltage: f64,
    dc_current: f64,
    winding_c: f64,
}

impl Plant {
    /// Synchronous speed at the rated frequency, rad/s (the dynamometer's
    /// range, the friction's reference).
    fn synchronous_speed(&self) -> f64 {
        std::f64::consts::TAU * self.cfg.supply.frequency / f64::from(self.cfg.supply.pole_pairs)
    }

    fn advance(&mut self) -> Snapshot {
        let dt = self.dt;
        // Supply.
        let target_v = if self.vfd_enabled {
            self.vfd_setpoint
        } else {
            0.0
        };
        let dv = self.cfg.vfd_slew_v_per_s * dt;
        self.vfd_output += (target_v - self.vfd_output).clamp(-dv, dv);
        // Shaft: the dynamometer holds its set point; without it the
        // machine runs up to (near) synchronous speed on the supply, or
        // coasts down with the supply off.
        let ws_rated = self.synchronous_speed();
        let ratio = self.frequency / self.cfg.supply.frequency;
        let ws = ws_rated * ratio;
        // The winding's resistance now, the reactances at the frequency.
        let mut c = at_frequency(&self.cfg.circuit, ratio);
        c.rs *= 1.0 + COPPER_ALPHA * (self.winding_c - 20.0);
        let supply = ImSupply {
            line_voltage: self.vfd_output.max(0.0),
            frequency: self.frequency,
            ..self.cfg.supply
        };
        let target_w = if self.dyno_enabled {
            self.dyno_setpoint
        } else if self.vfd_output > 0.0 {
            (1.0 - free_rotor_slip(&c, &supply, self.cfg.friction_windage_w)) * ws
        } else {
            0.0
        };
        let tau = self.cfg.dyno_time_constant_s.max(dt);
        let dw = ((target_w - self.speed) * dt / tau)
            .clamp(-self.cfg.dyno_max_accel * dt, self.cfg.dyno_max_accel * dt);
        self.speed += dw;
        self.angle += self.speed * dt;
        // Electrical, quasi-static.
        let slip = (1.0 - self.speed / ws).clamp(0.0, 1.0);
        let op = c.operating_point(&supply, slip);
        // The DC source, between two line terminals: its set current, or
        // less where that would need more than its compliance voltage.
        let (dc_voltage, dc_current) = if self.dc_enabled {
            let r = terminal_resistance(c.rs, self.cfg.supply.connection);
            let i = self.dc_setpoint.min(self.dc_compliance / r);
            (i * r, i)
        } else {
            (0.0, 0.0)
        };
        // Heating by the losses (input less air-gap mechanical power).
        let losses = (op.input_power - op.torque * self.speed).max(0.0) + dc_voltage * dc_current;
        // Friction and windage on the shaft, a torque ∝ ω.
        let friction = self.cfg.friction_windage_w / ws_rated * (self.speed / ws_rated);
        let rise = self.cfg.thermal_resistance_k_per_w * losses;
        let ttau = self.cfg.thermal_time_constant_s.max(dt);
        self.winding_c += (self.cfg.ambient_c + rise - self.winding_c) * dt / ttau;
        self.step += 1;
        Snapshot {
            line_voltage: op.line_voltage,
            line_current: op.line_current,
            input_power: op.input_power,
            torque: op.torque - friction,
            angle: self.angle,
            dc_voltage,
            dc_current,
            winding_c: self.winding_c,
        }
    }
}

/// The simulated supply: set point = RMS line voltage, V.
#[derive(Debug, Clone)]
pub struct SimVfd {
    plant: Arc<Mutex<Plant>>,
}

/// The simulated dynamometer: set point = shaft speed, rad/s.
#[derive(Debug, Clone)]
pub struct SimDyno {
    plant: Arc<Mutex<Plant>>,
}

/// The simulated DC source of the winding-resistance test: set point =
/// DC current between two line terminals, A. It refuses to connect while
/// the supply is on, and the supply refuses to run while it is connected.
#[derive(Debug, Clone)]
pub struct SimDcSource {
    plant: Arc<Mutex<Plant>>,
}

/// The simulated sensors.
#[derive(Debug)]
pub struct SimImSensors {
    plant: Arc<Mutex<Plant>>,
    channels: Vec<ChannelInfo>,
    /// The channels of the DC source's voltage and current, when fitted.
    dc_channels: Option<(usize, usize)>,
    /// The winding thermometer's channel, when fitted.
    temperature_channel: Option<usize>,
    rng: StdRng,
    noise: Option<Normal<f64>>,
    counts_per_rad: f64,
    pacing: Pacing,
}

/// Why a simulated induction-machine rig cannot be built.
#[derive(Debug, thiserror::Error)]
pub enum SimRigError {
    /// The circuit's parameters are not valid.
    #[error(transparent)]
    Circuit(#[from] ImCircuitError),
    /// The sampling rate is not a finite number above zero.
    #[error("sample rate {0} Hz must be > 0")]
    SampleRate(f64),
    /// The supply has no frequency above zero or no pole pair.
    #[error("the supply needs a frequency > 0 and at least one pole pair")]
    Supply,
    /// The measurement noise's level is not usable.
    #[error(transparent)]
    Noise(#[from] rand_distr::NormalError),
}

/// The rig: supply, dynamometer, sensors, sharing one plant.
pub fn sim_im_rig(cfg: SimImRigConfig) -> Result<(SimVfd, SimDyno, SimImSensors), SimRigError> {
    cfg.circuit.validate()?;
    if !(cfg.sample_rate_hz.is_finite() && cfg.sample_rate_hz > 0.0) {
        return Err(SimRigError::SampleRate(cfg.sample_rate_hz));
    }
    if cfg.supply.pole_pairs == 0
        || !(cfg.supply.frequency.is_finite() && cfg.supply.frequency > 0.0)
    {
        return Err(SimRigError::Supply);
    }
    let noise = (cfg.noise_relative > 0.0)
        .then(|| Normal::new(0.0, cfg.noise_relative))
        .transpose()?;
    let info = |quantity: &str, unit: &str| ChannelInfo {
        quantity: quantity.into(),
        unit: unit.into(),
        source: SENSORS_ID.into(),
        rate_hz: cfg.sample_rate_hz,
    };
    let mut channels = vec![
        info("line_voltage", "V"),
        info("line_current", "A"),
        info("input_power", "W"),
        info("encoder_count", "count"),
    ];
    if cfg.torque_sensor {
        channels.push(info("torque", "N*m"));
    }
    let dc_channels = cfg.dc_source_max_current.map(|_| {
        channels.push(info("dc_voltage", "V"));
        channels.push(info("dc_current", "A"));
        (channels.len() - 2, channels.len() - 1)
    });
    let temperature_channel = cfg.winding_sensor.then(|| {
        channels.push(info("winding_temperature", "degC"));
        channels.len() - 1
    });
    let counts_per_rad = 4.0 * f64::from(cfg.encoder_lines) / std::f64::consts::TAU;
    let rng = StdRng::seed_from_u64(cfg.seed);
    let plant = Arc::new(Mutex::new(Plant {
        dt: 1.0 / cfg.sample_rate_hz,
        winding_c: cfg.ambient_c,
        frequency: cfg.supply.frequency,
        cfg,
        vfd_setpoint: 0.0,
        vfd_output: 0.0,
        vfd_enabled: false,
        dyno_setpoint: 0.0,
        dyno_enabled: false,
        dc_setpoint: 0.0,
        dc_enabled: false,
        dc_compliance: f64::INFINITY,
        speed: 0.0,
        angle: 0.0,
        step: 0,
    }));
    Ok((
        SimVfd {
            plant: plant.clone(),
        },
        SimDyno {
            plant: plant.clone(),
        },
        SimImSensors {
            plant,
            channels,
            dc_channels,
            temperature_channel,
            rng,
            noise,
            counts_per_rad,
            pacing: Pacing::Virtual,
        },
    ))
}

impl SimImSensors {
    /// Winding temperature now, °C (the simulator's truth, for tests).
    pub fn winding_temperature(&self) -> f64 {
        lock_plant(&self.plant).winding_c
    }

    /// The channels of the DC source's voltage and current, when fitted.
    pub fn dc_channels(&self) -> Option<(usize, usize)> {
        self.dc_channels
    }

    /// The winding thermometer's channel, when fitted.
    pub fn temperature_channel(&self) -> Option<usize> {
        self.temperature_channel
    }

    /// Pace the stream at the wall clock: each batch is delivered when the
    /// wall-clock time since the first read reaches its data time, as on a
    /// real rig (the daemon and `run --realtime` use this).
    pub fn paced(mut self) -> SimImSensors {
        self.pacing = Pacing::wall_from_first_batch();
        self
    }

    /// Advance the plant by one sample period and read the sensors,
    /// without any pacing (for simulated devices that run the plant on
    /// their own clock).
    pub fn sample(&mut self) -> SampleBatch {
        let (snap, t_ns) = {
            let mut p = lock_plant(&self.plant);
            let snap = p.advance();
            (snap, (p.step as f64 * p.dt * 1e9).round() as u64)
        };
        let mut read = |v: f64| match &self.noise {
            Some(n) => v * (1.0 + n.sample(&mut self.rng)),
            None => v,
        };
        let mut samples = vec![
            Sample {
                channel: channel::LINE_VOLTAGE,
                value: read(snap.line_voltage),
            },
            Sample {
                channel: channel::LINE_CURRENT,
                value: read(snap.line_current),
            },
            Sample {
                channel: channel::INPUT_POWER,
                value: read(snap.input_power),
            },
            Sample {
                channel: channel::ENCODER,
                value: (snap.angle * self.counts_per_rad).floor(),
            },
        ];
        if lock_plant(&self.plant).cfg.torque_sensor {
            samples.push(Sample {
                channel: channel::TORQUE,
                value: read(snap.torque),
            });
        }
        if let Some((v, i)) = self.dc_channels {
            samples.push(Sample {
                channel: v,
                value: read(snap.dc_voltage),
            });
            samples.push(Sample {
                channel: i,
                value: read(snap.dc_current),
            });
        }
        if let Some(ch) = self.temperature_channel {
            let noise = match self.noise {
                Some(_) => {
                    let z: f64 = StandardNormal.sample(&mut self.rng);
                    WINDING_SENSOR_SIGMA_K * z
                }
                None => 0.0,
            };
            samples.push(Sample {
                channel: ch,
                value: snap.winding_c + noise,
            });
        }
        SampleBatch { t_ns, samples }
    }
}

impl SimVfd {
    /// Whether the supply's output is on (the simulator's truth, for tests).
    pub fn output_enabled(&self) -> bool {
        lock_plant(&self.plant).vfd_enabled
    }

    /// The supply's output frequency, Hz.
    pub fn frequency(&self) -> f64 {
        lock_plant(&self.plant).frequency
    }

    /// The rig's DC source, when the configuration fits one.
    pub fn dc_source(&self) -> Option<SimDcSource> {
        lock_plant(&self.plant)
            .cfg
            .dc_source_max_current
            .map(|_| SimDcSource {
                plant: self.plant.clone(),
            })
    }
}

impl SimDcSource {
    /// Set the compliance voltage, V: the source drives its set current
    /// unless the winding would need more than this.
    pub fn set_compliance_voltage(&mut self, volts: f64) -> Result<(), DriverError> {
        if !(volts.is_finite() && volts >= 0.0) {
            return Err(DriverError::Device {
                device: DC_SOURCE_ID.into(),
                reason: format!("compliance voltage {volts} V must be ≥ 0"),
            });
        }
        lock_plant(&self.plant).dc_compliance = volts;
        Ok(())
    }
}

impl SimDyno {
    /// The speed set point, rad/s, and whether the dynamometer holds it
    /// (the simulator's truth, for tests).
    pub fn command(&self) -> (f64, bool) {
        let p = lock_plant(&self.plant);
        (p.dyno_setpoint, p.dyno_enabled)
    }
}

#[async_trait]
impl PowerStage for SimVfd {
    fn id(&self) -> &str {
        VFD_ID
    }

    fn capabilities(&self) -> StageCapabilities {
        StageCapabilities {
            current_limit: false,
            max_setpoint: lock_plant(&self.plant).cfg.supply.line_voltage,
        }
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        let max = p.cfg.supply.line_voltage;
        check_setpoint(VFD_ID, "voltage", "V", value, max, 1.0001)?;
        p.vfd_setpoint = value;
        Ok(())
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        if enabled && p.dc_enabled {
            return Err(DriverError::Device {
                device: VFD_ID.into(),
                reason: "the DC source is connected to the winding: disconnect it first".into(),
            });
        }
        p.vfd_enabled = enabled;
        Ok(())
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        p.vfd_setpoint = 0.0;
        p.vfd_enabled = false;
        Ok(())
    }

    async fn read_output_enabled(&mut self) -> Result<Option<bool>, DriverError> {
        Ok(Some(lock_plant(&self.plant).vfd_enabled))
    }

    /// The output frequency, in (0, rated] Hz (the simulated machine runs
    /// at its rated frequency or below, its reactances in proportion).
    async fn set_frequency(&mut self, hz: f64) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        let rated = p.cfg.supply.frequency;
        check_frequency(VFD_ID, hz, rated, 1.0001)?;
        p.frequency = hz.min(rated);
        Ok(())
    }
}

#[async_trait]
impl PowerStage for SimDyno {
    fn id(&self) -> &str {
        DYNO_ID
    }

    fn capabilities(&self) -> StageCapabilities {
        let p = lock_plant(&self.plant);
        StageCapabilities {
            current_limit: false,
            max_setpoint: 1.2 * p.synchronous_speed(),
        }
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        let max = 1.2 * p.synchronous_speed();
        check_setpoint(DYNO_ID, "speed", "rad/s", value, max, 1.0)?;
        p.dyno_setpoint = value;
        Ok(())
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        lock_plant(&self.plant).dyno_enabled = enabled;
        Ok(())
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        // A dynamometer's safe state brakes the shaft to rest.
        let mut p = lock_plant(&self.plant);
        p.dyno_setpoint = 0.0;
        p.dyno_enabled = true;
        Ok(())
    }
}

#[async_trait]
impl PowerStage for SimDcSource {
    fn id(&self) -> &str {
        DC_SOURCE_ID
    }

    fn capabilities(&self) -> StageCapabilities {
        StageCapabilities {
            current_limit: false,
            max_setpoint: lock_plant(&self.plant)
                .cfg
                .dc_source_max_current
                .unwrap_or(0.0),
        }
    }

    async fn set_setpoint(&mut self, value: f64) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        let max = p.cfg.dc_source_max_current.unwrap_or(0.0);
        check_setpoint(DC_SOURCE_ID, "DC current", "A", value, max, 1.0)?;
        p.dc_setpoint = value;
        Ok(())
    }

    async fn set_output_enabled(&mut self, enabled: bool) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        if enabled && (p.vfd_enabled || p.vfd_output > 0.0) {
            return Err(DriverError::Device {
                device: DC_SOURCE_ID.into(),
                reason: "the supply is on: the DC source connects only to a dead winding".into(),
            });
        }
        p.dc_enabled = enabled;
        Ok(())
    }

    async fn safe_state(&mut self) -> Result<(), DriverError> {
        let mut p = lock_plant(&self.plant);
        p.dc_setpoint = 0.0;
        p.dc_enabled = false;
        Ok(())
    }
}

#[async_trait]
impl SensorStream for SimImSensors {
    fn id(&self) -> &str {
        SENSORS_ID
    }

    fn channels(&self) -> &[ChannelInfo] {
        &self.channels
    }

    async fn next_batch(&mut self) -> Result<SampleBatch, DriverError> {
        self.pacing.start();
        let batch = self.sample();
        let step = lock_plant(&self.plant).step;
        self.pacing.wait(batch.t_ns, step).await;
        Ok(batch)
    }

    fn virtual_clock(&self) -> bool {
        self.pacing.is_virtual()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Connection, ImModel};

    fn rig() -> SimImRigConfig {
        let circuit = ImCircuit::from_values(
            ImModel::Double,
            &[0.8659, 3.4224, 119.6437, 1.9282, 0.7346, 0.2346, 3.2332],
        )
        .unwrap();
        let supply = ImSupply {
            line_voltage: 440.0,
            frequency: 50.0,
            connection: Connection::Star,
            pole_pairs: 2,
        };
        SimImRigConfig::new(circuit, supply)
    }

    /// Switch the supply on at `volts` and run the plant `steps` sample
    /// periods: the last batch.
    async fn supply_on(
        vfd: &mut SimVfd,
        sensors: &mut SimImSensors,
        volts: f64,
        steps: usize,
    ) -> SampleBatch {
        vfd.set_setpoint(volts).await.unwrap();
        vfd.set_output_enabled(true).await.unwrap();
        let mut last = None;
        for _ in 0..steps {
            last = Some(sensors.next_batch().await.unwrap());
        }
        last.unwrap()
    }

    #[tokio::test]
    async fn the_dc_source_reads_the_terminal_resistance_and_is_interlocked_with_the_supply() {
        let mut cfg = rig();
        cfg.noise_relative = 0.0;
        cfg.thermal_resistance_k_per_w = 0.0;
        assert!(sim_im_rig(cfg.clone()).unwrap().0.dc_source().is_none());
        cfg.dc_source_max_current = Some(5.0);
        let (mut vfd, _, mut sensors) = sim_im_rig(cfg).unwrap();
        let mut dc = vfd.dc_source().unwrap();
        let names: Vec<&str> = sensors
            .channels()
            .iter()
            .map(|c| c.quantity.as_str())
            .collect();
        assert_eq!(names[5..], ["dc_voltage", "dc_current"]);
        assert!(
            dc.set_setpoint(6.0).await.is_err(),
            "above its largest current"
        );
        dc.set_setpoint(4.0).await.unwrap();
        dc.set_output_enabled(true).await.unwrap();
        let e = vfd.set_output_enabled(true).await.unwrap_err();
        assert!(e.to_string().contains("DC source"), "{e}");
        let b = sensors.next_batch().await.unwrap();
        // Star: two phases in series.
        assert!((b.value(5).unwrap() - 4.0 * 2.0 * 0.8659).abs() < 1e-12);
        assert_eq!(b.value(6), Some(4.0));
        dc.safe_state().await.unwrap();
        vfd.set_setpoint(400.0).await.unwrap();
        vfd.set_output_enabled(true).await.unwrap();
        sensors.next_batch().await.unwrap();
        let e = dc.set_output_enabled(true).await.unwrap_err();
        assert!(e.to_string().contains("supply is on"), "{e}");
    }

    #[tokio::test]
    async fn the_free_rotor_turns_below_synchronous_speed_with_friction() {
        let ws = std::f64::consts::PI * 50.0;
        let mut speeds = Vec::new();
        for friction in [0.0, 200.0] {
            let mut cfg = rig();
            cfg.noise_relative = 0.0;
            cfg.supply.line_voltage = 400.0;
            cfg.friction_windage_w = friction;
            let (mut vfd, _, mut sensors) = sim_im_rig(cfg).unwrap();
            let b = supply_on(&mut vfd, &mut sensors, 400.0, 2500).await;
            let counts = b.value(channel::ENCODER).unwrap();
            // The speed from the plant itself: the angle's growth per step.
            let speed = lock_plant(&sensors.plant).speed;
            assert!(counts > 0.0);
            // The torque sensor sees the shaft's torque: nothing is coupled.
            assert!(b.value(channel::TORQUE).unwrap().abs() < 0.05, "{b:?}");
            speeds.push(speed);
        }
        assert!((speeds[0] - ws).abs() < 1e-9, "{speeds:?}");
        let slip = 1.0 - speeds[1] / ws;
        assert!(slip > 1e-4 && slip < 0.02, "{slip}");
    }

    #[tokio::test]
    async fn a_reduced_frequency_scales_the_reactances_and_the_thermometer_reads_the_winding() {
        let mut cfg = rig();
        cfg.noise_relative = 0.0;
        cfg.thermal_resistance_k_per_w = 0.0;
        cfg.ambient_c = 31.5;
        cfg.winding_sensor = true;
        let (mut vfd, mut dyno, mut sensors) = sim_im_rig(cfg.clone()).unwrap();
        let t = sensors.temperature_channel().unwrap();
        assert_eq!(sensors.channels()[t].quantity, "winding_temperature");
        for bad in [0.0, 50.1, f64::NAN] {
            assert!(vfd.set_frequency(bad).await.is_err(), "{bad} Hz");
        }
        dyno.set_setpoint(0.0).await.unwrap();
        dyno.set_output_enabled(true).await.unwrap();
        vfd.set_frequency(12.5).await.unwrap();
        assert_eq!(vfd.frequency(), 12.5);
        let b = supply_on(&mut vfd, &mut sensors, 40.0, 200).await;
        let mut c = at_frequency(&cfg.circuit, 0.25);
        c.rs *= 1.0 + COPPER_ALPHA * (31.5 - 20.0);
        let supply = ImSupply {
            line_voltage: 40.0,
            frequency: 12.5,
            ..cfg.supply
        };
        let want = c.operating_point(&supply, 1.0).line_current;
        let got = b.value(channel::LINE_CURRENT).unwrap();
        assert!((got / want - 1.0).abs() < 1e-9, "{got} A against {want} A");
        // Far from the rated-frequency current at that voltage.
        let mut rated = cfg.circuit;
        rated.rs = c.rs;
        let at_50 = rated
            .operating_point(
                &ImSupply {
                    line_voltage: 40.0,
                    ..cfg.supply
                },
                1.0,
            )
            .line_current;
        assert!(got > 1.5 * at_50, "{got} A, {at_50} A at 50 Hz");
        assert_eq!(b.value(t), Some(31.5));
    }

    #[tokio::test]
    async fn the_dc_source_stops_at_its_compliance_voltage() {
        let mut cfg = rig();
        cfg.noise_relative = 0.0;
        cfg.thermal_resistance_k_per_w = 0.0;
        cfg.dc_source_max_current = Some(5.0);
        let (vfd, _, mut sensors) = sim_im_rig(cfg).unwrap();
        let mut dc = vfd.dc_source().unwrap();
        let (v, i) = sensors.dc_channels().unwrap();
        assert!(dc.set_compliance_voltage(-1.0).is_err());
        dc.set_compliance_voltage(2.0).unwrap();
        dc.set_setpoint(4.0).await.unwrap();
        dc.set_output_enabled(true).await.unwrap();
        let b = sensors.next_batch().await.unwrap();
        // 2 V across 2·Rs: less than the 4 A set.
        assert_eq!(b.value(v), Some(2.0));
        assert!((b.value(i).unwrap() - 2.0 / (2.0 * 0.8659)).abs() < 1e-12);
    }

    #[test]
    fn a_bad_rate_and_a_bad_supply_are_told_apart() {
        let mut cfg = rig();
        cfg.sample_rate_hz = 0.0;
        let e = sim_im_rig(cfg).unwrap_err();
        assert!(matches!(e, SimRigError::SampleRate(r) if r == 0.0), "{e:?}");
        assert_eq!(e.to_string(), "sample rate 0 Hz must be > 0");
        let mut cfg = rig();
        cfg.supply.pole_pairs = 0;
        let e = sim_im_rig(cfg).unwrap_err();
        assert!(matches!(e, SimRigError::Supply), "{e:?}");
    }

    #[tokio::test(start_paused = true)]
    async fn paced_batches_come_at_the_wall_clock_unpaced_at_once() {
        // 500 Hz: 100 batches are 0.2 s of data.
        let (_, _, sensors) = sim_im_rig(rig()).unwrap();
        let mut paced = sensors.paced();
        let t0 = tokio::time::Instant::now();
        for _ in 0..100 {
            paced.next_batch().await.unwrap();
        }
        let waited = t0.elapsed().as_secs_f64();
        assert!((waited - 0.2).abs() < 1e-3, "{waited}");

        let (_, _, mut free) = sim_im_rig(rig()).unwrap();
        let t0 = tokio::time::Instant::now();
        for _ in 0..100 {
            free.next_batch().await.unwrap();
        }
        assert_eq!(t0.elapsed().as_secs_f64(), 0.0);
    }
}
