//! Configuration of an `im_slip_sweep` run on the simulated
//! induction-machine rig (TOML, `config/sim-im.toml`), validated.
//!
//! The file has the DC configuration's layout (`[motor]`, `[rig]`,
//! `[limits]`, `[test]`) with the induction machine's keys; a file whose
//! `test.plan` is `"im_slip_sweep"` is one of these ([`is_im_sweep_config`]).
//! Unknown keys are refused; every error names the file and the line.

use serde::Deserialize;

use super::{ImSweepPlan, SimImRigConfig};
use crate::identify::slip_grid;
use crate::model::{Connection, ImCircuit, ImModel, ImParam, ImSupply};

/// Whether `text` is an induction-machine sweep configuration (its
/// `test.plan` is `"im_slip_sweep"`).
pub fn is_im_sweep_config(text: &str) -> bool {
    toml::from_str::<toml::Table>(text)
        .ok()
        .and_then(|t| {
            t.get("test")?
                .get("plan")?
                .as_str()
                .map(|p| p == "im_slip_sweep")
        })
        .unwrap_or(false)
}

/// The circuit to identify named in a recorded configuration (`test.model`).
pub fn im_model_of_config(text: &str) -> Option<ImModel> {
    let t = toml::from_str::<toml::Table>(text).ok()?;
    ImModel::parse(t.get("test")?.get("model")?.as_str()?)
}

/// A validated sweep configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct ImRunConfig {
    /// Where it came from.
    pub source: String,
    /// The text as given (recorded in the MCAP metadata).
    pub text: String,
    /// Motor id.
    pub motor_id: String,
    /// Nameplate (JSON object).
    pub nameplate: serde_json::Value,
    /// The simulated rig.
    pub rig: SimImRigConfig,
    /// The test plan.
    pub plan: ImSweepPlan,
    /// The circuit identification fits.
    pub model: ImModel,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    motor: RawMotor,
    rig: RawRig,
    limits: RawLimits,
    test: RawTest,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotor {
    id: String,
    nameplate: toml::Table,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRig {
    backend: String,
    #[serde(rename = "sample_rate_Hz")]
    sample_rate_hz: f64,
    simulated: RawSim,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSim {
    motor: toml::Table,
    supply: RawSupply,
    dynamometer: RawDyno,
    sensors: RawSensors,
    thermal: RawThermal,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSupply {
    #[serde(rename = "slew_V_per_s")]
    slew: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDyno {
    time_constant_s: f64,
    max_accel_rad_s2: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSensors {
    seed: u64,
    noise_relative: f64,
    encoder_lines: u32,
    torque_sensor: bool,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawThermal {
    #[serde(rename = "resistance_K_per_W")]
    resistance: f64,
    time_constant_s: f64,
    #[serde(rename = "ambient_C")]
    ambient: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLimits {
    #[serde(rename = "max_current_A")]
    max_current: f64,
    max_i2t_s: f64,
    i2t_time_constant_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTest {
    plan: String,
    model: String,
    #[serde(rename = "voltages_V")]
    voltages: Vec<f64>,
    points: usize,
    min_slip: f64,
    #[serde(rename = "hot_current_A")]
    hot_current: f64,
    hot_point_max_s: f64,
    cooldown_s: f64,
    settle: RawSettle,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSettle {
    window_samples: usize,
    tolerance: f64,
    average_samples: usize,
    timeout_s: f64,
}

fn number(t: &toml::Table, key: &str) -> Option<f64> {
    match t.get(key)? {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

impl ImRunConfig {
    /// Read and validate a file.
    pub fn load(path: &std::path::Path) -> Result<ImRunConfig, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        ImRunConfig::parse(&path.display().to_string(), &text)
    }

    /// Parse and validate `text`; `source` names it in errors.
    pub fn parse(source: &str, text: &str) -> Result<ImRunConfig, String> {
        let raw: Raw = toml::from_str(text).map_err(|e| {
            let start = e.span().map(|s| s.start).unwrap_or(0).min(text.len());
            let line = text[..start].matches('\n').count() + 1;
            format!("{source}:{line}: {}", e.message())
        })?;
        let bad = |what: String| format!("{source}: {what}");
        if raw.rig.backend != "simulated" {
            return Err(bad(format!(
                "rig.backend {:?}: only \"simulated\" is available",
                raw.rig.backend
            )));
        }
        if raw.test.plan != "im_slip_sweep" {
            return Err(bad(format!(
                "test.plan {:?} is not im_slip_sweep",
                raw.test.plan
            )));
        }
        let model = ImModel::parse(&raw.test.model).ok_or_else(|| {
            bad(format!(
                "test.model {:?}: want single, single-fe, double or double-fe",
                raw.test.model
            ))
        })?;
        let plate = &raw.motor.nameplate;
        let need = |key: &str| {
            number(plate, key)
                .ok_or_else(|| bad(format!("motor.nameplate.{key} is missing or not a number")))
        };
        let (voltage, current, frequency, poles) = (
            need("voltage_V")?,
            need("current_A")?,
            need("frequency_Hz")?,
            need("poles")?,
        );
        let connection = plate
            .get("connection")
            .and_then(|v| v.as_str())
            .and_then(Connection::parse)
            .ok_or_else(
                || bad("motor.nameplate.connection must be \"star\" or \"delta\"".into()),
            )?;
        if poles < 2.0 || poles % 2.0 != 0.0 {
            return Err(bad(format!(
                "motor.nameplate.poles = {poles} must be an even number ≥ 2"
            )));
        }
        // The circuit: the model's keys, Ω per phase.
        let m = &raw.rig.simulated.motor;
        let truth_model = ImModel::parse(m.get("model").and_then(|v| v.as_str()).unwrap_or(""))
            .ok_or_else(|| {
                bad(
                    "rig.simulated.motor.model must be single, single-fe, double or double-fe"
                        .into(),
                )
            })?;
        for key in m.keys() {
            if key != "model" && !truth_model.params().iter().any(|p| p.key() == key) {
                return Err(bad(format!(
                    "rig.simulated.motor.{key} is not a {truth_model} parameter"
                )));
            }
        }
        let values: Result<Vec<f64>, String> = truth_model
            .params()
            .iter()
            .map(|p: &ImParam| {
                number(m, p.key())
                    .ok_or_else(|| bad(format!("rig.simulated.motor.{p} (ohm) is missing")))
            })
            .collect();
        let circuit = ImCircuit::from_values(truth_model, &values?)
            .map_err(|e| bad(format!("rig.simulated.motor: {e}")))?;
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(v)
            } else {
                Err(bad(format!("{name} = {v} must be a finite number > 0")))
            }
        };
        positive("rig.sample_rate_Hz", raw.rig.sample_rate_hz)?;
        positive("limits.max_current_A", raw.limits.max_current)?;
        positive("test.hot_current_A", raw.test.hot_current)?;
        if raw.test.voltages.is_empty()
            || raw
                .test
                .voltages
                .iter()
                .any(|v| !(v.is_finite() && *v > 0.0 && *v <= voltage * 1.1))
        {
            return Err(bad(format!(
                "test.voltages_V must be a non-empty list in (0, {:.0}] V",
                voltage * 1.1
            )));
        }
        if !(raw.test.points >= 5 && raw.test.min_slip > 0.0 && raw.test.min_slip < 0.2) {
            return Err(bad(
                "test.points must be ≥ 5 and test.min_slip in (0, 0.2)".into()
            ));
        }
        let supply = ImSupply {
            line_voltage: voltage * 1.1,
            frequency,
            connection,
            pole_pairs: (poles / 2.0) as u32,
        };
        let s = &raw.rig.simulated;
        let rig = SimImRigConfig {
            circuit,
            supply,
            sample_rate_hz: raw.rig.sample_rate_hz,
            dyno_time_constant_s: positive(
                "rig.simulated.dynamometer.time_constant_s",
                s.dynamometer.time_constant_s,
            )?,
            dyno_max_accel: positive(
                "rig.simulated.dynamometer.max_accel_rad_s2",
                s.dynamometer.max_accel_rad_s2,
            )?,
            vfd_slew_v_per_s: positive("rig.simulated.supply.slew_V_per_s", s.supply.slew)?,
            noise_relative: s.sensors.noise_relative.max(0.0),
            encoder_lines: s.sensors.encoder_lines.max(1),
            torque_sensor: s.sensors.torque_sensor,
            thermal_resistance_k_per_w: s.thermal.resistance.max(0.0),
            thermal_time_constant_s: positive(
                "rig.simulated.thermal.time_constant_s",
                s.thermal.time_constant_s,
            )?,
            ambient_c: s.thermal.ambient,
            seed: s.sensors.seed,
        };
        let st = &raw.test.settle;
        let plan = ImSweepPlan {
            voltages: raw.test.voltages.clone(),
            slips: slip_grid(raw.test.points, raw.test.min_slip),
            frequency,
            pole_pairs: supply.pole_pairs,
            settle_window: st.window_samples.max(2),
            settle_tolerance: positive("test.settle.tolerance", st.tolerance)?,
            average_samples: st.average_samples.max(1),
            max_point_s: positive("test.settle.timeout_s", st.timeout_s)?,
            rated_current: current,
            max_current: raw.limits.max_current,
            hot_current: raw.test.hot_current,
            hot_point_max_s: positive("test.hot_point_max_s", raw.test.hot_point_max_s)?,
            cooldown_s: raw.test.cooldown_s.max(0.0),
            max_i2t_s: positive("limits.max_i2t_s", raw.limits.max_i2t_s)?,
            i2t_time_constant_s: positive(
                "limits.i2t_time_constant_s",
                raw.limits.i2t_time_constant_s,
            )?,
            encoder_counts_per_rev: 4.0 * f64::from(rig.encoder_lines),
        };
        let nameplate =
            serde_json::to_value(plate).map_err(|e| bad(format!("motor.nameplate: {e}")))?;
        Ok(ImRunConfig {
            source: source.into(),
            text: text.into(),
            motor_id: raw.motor.id,
            nameplate,
            rig,
            plan,
            model,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SIM_IM: &str = include_str!("../../config/sim-im.toml");

    #[test]
    fn shipped_config_parses() {
        assert!(is_im_sweep_config(SIM_IM));
        assert_eq!(im_model_of_config(SIM_IM), Some(ImModel::Double));
        let c = ImRunConfig::parse("sim-im.toml", SIM_IM).unwrap();
        assert_eq!(c.rig.circuit.model(), ImModel::Double);
        assert_eq!(c.plan.pole_pairs, 2);
        assert_eq!(c.nameplate["connection"], "star");
        assert!(!is_im_sweep_config(include_str!(
            "../../config/sim-dc.toml"
        )));
    }

    #[test]
    fn errors_name_the_file_and_the_key_or_line() {
        let e = ImRunConfig::parse("x.toml", &SIM_IM.replace("Rr2 =", "Rq2 =")).unwrap_err();
        assert!(e.contains("x.toml") && e.contains("Rq2"), "{e}");
        let e =
            ImRunConfig::parse("x.toml", &SIM_IM.replace("points = ", "pointz = ")).unwrap_err();
        assert!(e.starts_with("x.toml:") && e.contains("pointz"), "{e}");
        let e = ImRunConfig::parse(
            "x.toml",
            &SIM_IM.replace("connection = \"star\"", "connection = \"zigzag\""),
        )
        .unwrap_err();
        assert!(e.contains("connection"), "{e}");
    }
}
