//! The fault matrix (`docs/reliability.md`): one test per row, each a
//! fault injected through the configuration's `[[fault]]` array into a
//! shipped rig (the in-process simulation, or the simulation served
//! behind Modbus TCP or RTU, whose protocol faults then go through the
//! real client stack), run through `motorbench run --config` or the
//! daemon's HTTP API, and the outcome the row promises checked in what
//! the test left behind (exit code, record, daemon state):
//!
//! - retried: the test completes, the retries counted;
//! - degraded: the test completes with a warning event saying why;
//! - aborted: the test ends as aborted (exit code 3), the supervisor's
//!   stop with its cause and the rig commanded safe in the record.
//!
//! No assertion is on a duration.

use std::path::{Path, PathBuf};

use motorbench::record::{read_mcap, EventLevel, Record};

use crate::common::{self, replay::only_mcap};

/// Held by the tests that run on the wall clock (the protocol-served
/// rigs): they run one after the other, so as not to disturb each
/// other's sampling.
static REALTIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

fn realtime() -> tokio::sync::MutexGuard<'static, ()> {
    REALTIME.blocking_lock()
}

/// A shipped configuration with `supervisor` keys set in its
/// `[supervisor]` section (replacing the same keys), `faults` appended
/// and each `(from, to)` of `replace` made, written into `dir` with its
/// device profiles' paths made absolute.
fn config_with(
    shipped: &str,
    supervisor: &str,
    faults: &str,
    replace: &[(&str, &str)],
    dir: &Path,
) -> PathBuf {
    let config_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let mut text = std::fs::read_to_string(config_dir.join(shipped))
        .unwrap()
        .replace(
            "profile = \"devices/",
            &format!("profile = \"{}/devices/", config_dir.display()),
        )
        .replace(
            "dbc = \"devices/",
            &format!("dbc = \"{}/devices/", config_dir.display()),
        );
    for (from, to) in replace {
        assert!(text.contains(from), "{shipped} has no `{from}`");
        text = text.replace(from, to);
    }
    let keys: Vec<&str> = supervisor
        .lines()
        .filter(|l| !l.trim().is_empty())
        .collect();
    if !keys.is_empty() {
        let names: Vec<String> = keys
            .iter()
            .map(|k| format!("{} ", k.split('=').next().unwrap().trim()))
            .collect();
        text = text
            .lines()
            .filter(|l| !names.iter().any(|n| l.starts_with(n.as_str())))
            .collect::<Vec<_>>()
            .join("\n");
        match text.find("\n[supervisor]") {
            Some(at) => {
                let end = at + text[at + 1..].find('\n').unwrap() + 1;
                text.insert_str(end + 1, &format!("{}\n", keys.join("\n")));
            }
            None => text.push_str(&format!("\n[supervisor]\n{}\n", keys.join("\n"))),
        }
    }
    let path = dir.join("rig.toml");
    std::fs::write(&path, format!("{text}\n{faults}\n")).unwrap();
    path
}

/// What `motorbench run` left: its exit code, stderr and record.
struct Ran {
    code: Option<i32>,
    stderr: String,
    record: Record,
    _dir: tempfile::TempDir,
}

/// The messages of `record`'s events at `level`.
fn events(record: &Record, level: EventLevel) -> Vec<&str> {
    record
        .events
        .iter()
        .filter(|(_, e)| e.level == level)
        .map(|(_, e)| e.message.as_str())
        .collect()
}

/// A link's retry (or reconnect) is counted among `record`'s events.
fn assert_link_retried(record: &Record) {
    let links = events(record, EventLevel::Info);
    assert!(
        links
            .iter()
            .any(|m| m.starts_with("link ") && (m.contains("retry ") || m.contains("reconnect "))),
        "no retry counted in {links:?}"
    );
}

/// The supervisor found the stage still enabled after its safe command
/// and disabled the output.
fn assert_escalated_to_disable(record: &Record) {
    let aborts = events(record, EventLevel::Abort);
    assert!(
        aborts
            .iter()
            .any(|m| m.contains("output still enabled after the safe command")),
        "{aborts:?}"
    );
    assert!(
        aborts.iter().any(|m| m.ends_with("output disabled")),
        "{aborts:?}"
    );
}

impl Ran {
    fn events(&self, level: EventLevel) -> Vec<&str> {
        events(&self.record, level)
    }

    /// The supervisor's account of its stop.
    fn stop(&self) -> &str {
        self.events(EventLevel::Info)
            .into_iter()
            .find(|m| m.starts_with("safety supervisor: "))
            .unwrap_or_else(|| panic!("no supervisor stop in {:?}", self.record.events))
    }

    /// The plan's abort event (not the supervisor's escalation steps).
    fn plan_abort(&self) -> &str {
        self.events(EventLevel::Abort)
            .into_iter()
            .find(|m| !m.starts_with("safety supervisor: "))
            .unwrap_or_else(|| panic!("no abort event in {:?}", self.record.events))
    }

    /// Aborted (exit code 3) by the supervisor for `cause` (its text
    /// starts so), the rig commanded to its safe state.
    fn assert_aborted_safe(&self, cause: &str) {
        assert_eq!(self.code, Some(3), "{}", self.stderr);
        let stop = self.stop();
        assert!(
            stop.starts_with(&format!("safety supervisor: {cause}")),
            "{stop}"
        );
        assert!(stop.contains("rig commanded to its safe state"), "{stop}");
        let abort = self.plan_abort();
        assert!(abort.contains("safe state"), "{abort}");
        assert!(!abort.contains("FAILED"), "{abort}");
    }

    /// Completed (exit code 0), a link's retries (or reconnects) in the
    /// record.
    fn assert_retried(&self) {
        assert_eq!(self.code, Some(0), "{}", self.stderr);
        assert!(self.events(EventLevel::Abort).is_empty());
        assert_link_retried(&self.record);
    }

    /// Completed (exit code 0) with a warning containing `warning`.
    fn assert_degraded(&self, warning: &str) {
        assert_eq!(self.code, Some(0), "{}", self.stderr);
        self.assert_warned(warning);
    }

    /// Ran to its end without an abort, a warning containing `warning` in
    /// its events and its report.
    fn assert_warned(&self, warning: &str) {
        let warnings = self.events(EventLevel::Warn);
        assert!(
            warnings.iter().any(|w| w.contains(warning)),
            "no warning with `{warning}` in {warnings:?}"
        );
        assert!(self.events(EventLevel::Abort).is_empty());
        // The report carries it too, for whoever reads it after the run.
        let result = self
            .record
            .recorded_result
            .as_ref()
            .expect("a completed test records its result");
        let listed: Vec<&str> = result["test_warnings"]
            .as_array()
            .map(|a| a.iter().filter_map(|w| w.as_str()).collect())
            .unwrap_or_default();
        assert!(
            listed
                .iter()
                .any(|w| w.starts_with("at test time ") && w.contains(warning)),
            "no test warning with `{warning}` in the report: {listed:?}"
        );
    }
}

/// `motorbench run --config` of `shipped` with `faults` appended.
fn run(shipped: &str, faults: &str) -> Ran {
    run_with(shipped, "", faults, &[])
}

/// `motorbench run --config` of `shipped` as [`config_with`] makes it.
fn run_with(shipped: &str, supervisor: &str, faults: &str, replace: &[(&str, &str)]) -> Ran {
    let dir = tempfile::tempdir().unwrap();
    let config = config_with(shipped, supervisor, faults, replace, dir.path());
    let out_dir = dir.path().join("out");
    let out = common::motorbench(&[
        "run",
        "--config",
        config.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--no-diagnose",
    ]);
    let (_, stderr) = common::text(&out);
    assert!(out_dir.exists(), "no record written: {stderr}");
    let record = read_mcap(&only_mcap(&out_dir)).unwrap();
    Ran {
        code: out.status.code(),
        stderr,
        record,
        _dir: dir,
    }
}

const DC: &str = "sim-dc.toml";

// ---- DC, simulated rig, `motorbench run` ----

#[test]
fn dc_sim_run_nan_current_aborts_safe() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"armature_current\"\n",
    );
    r.assert_aborted_safe("limit tripped: current NaN");
}

#[test]
fn dc_sim_run_inf_voltage_aborts_safe() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"inf\"\nat_s = 1.0\ntarget = \"armature_voltage\"\n",
    );
    r.assert_aborted_safe("limit tripped: voltage inf");
}

#[test]
fn dc_sim_run_current_spike_beyond_the_limit_aborts_safe() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"spike\"\nat_s = 1.0\ntarget = \"armature_current\"\nvalue = 20\n",
    );
    r.assert_aborted_safe("limit tripped: current");
}

#[test]
fn dc_sim_run_clock_jump_back_aborts_safe() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"clock_jump\"\nat_s = 1.0\nvalue = -0.5\n",
    );
    r.assert_aborted_safe("clock jump: the sample time went from");
}

#[test]
fn dc_sim_run_clock_jump_ahead_aborts_safe() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"clock_jump\"\nat_s = 1.0\nvalue = 2.0\n",
    );
    r.assert_aborted_safe("clock jump: the sample time went from");
}

#[test]
fn dc_sim_run_stuck_current_warns() {
    let r = run_with(
        DC,
        "stuck_after_s = 0.5",
        "[[fault]]\nkind = \"stuck\"\nat_s = 0.3\ntarget = \"armature_current\"\n",
        &[],
    );
    r.assert_degraded("stuck sensor? `armature_current` has held exactly");
}

#[test]
fn dc_sim_run_encoder_losing_every_count_warns() {
    // A shaft that seems not to turn never settles: a short settle
    // timeout keeps the test short.
    let r = run_with(
        DC,
        "stuck_after_s = 0.5",
        "[[fault]]\nkind = \"encoder_loses_counts\"\nat_s = 0.3\n",
        &[
            ("timeout_s = 10 ", "timeout_s = 1 "),
            ("coastdown = true", "coastdown = false"),
            (
                "levels_V = [60, 248, 60, 154, 248, 107, 201, 60]",
                "levels_V = [60, 248]",
            ),
        ],
    );
    r.assert_degraded("stuck sensor? `encoder_count` has held exactly");
}

#[test]
fn dc_sim_run_encoder_losing_half_its_counts_warns_against_the_nameplate() {
    // Half of every count lost: the speed reads half, which the model
    // fits as well with twice the K; only the nameplate tells.
    let r = run(
        DC,
        "[[fault]]\nkind = \"encoder_loses_counts\"\nat_s = 0\nvalue = 0.5\n",
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let result = r.record.recorded_result.as_ref().expect("a result");
    let warnings: Vec<&str> = result["warnings"]
        .as_array()
        .expect("warnings")
        .iter()
        .filter_map(|w| w.as_str())
        .collect();
    assert!(
        warnings
            .iter()
            .any(|w| w.starts_with("nameplate: K = ") && w.contains("lines per revolution")),
        "{warnings:?}"
    );
}

#[test]
fn dc_sim_run_supply_current_limit_warns() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"current_limit\"\nat_s = 0\nvalue = 0.15\n",
    );
    r.assert_degraded("the segment's voltage is not the commanded step");
    assert!(!r.record.supply_limits.is_empty());
}

#[test]
fn dc_sim_run_stage_ignoring_the_safe_command_is_disabled() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"ignore_safe_state\"\nat_s = 0\n\
         [[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"armature_current\"\n",
    );
    r.assert_aborted_safe("limit tripped: current NaN");
    assert_escalated_to_disable(&r.record);
}

#[test]
fn dc_sim_run_stage_ignoring_the_disable_gets_the_last_resort() {
    let dir = tempfile::tempdir().unwrap();
    let marker = dir.path().join("contactor-opened");
    let r = run_with(
        DC,
        &format!(
            "last_resort_command = [\"touch\", \"{}\"]",
            marker.display()
        ),
        "[[fault]]\nkind = \"ignore_disable\"\nat_s = 0\n\
         [[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"armature_current\"\n",
        &[],
    );
    r.assert_aborted_safe("limit tripped: current NaN");
    let aborts = r.events(EventLevel::Abort);
    assert!(
        aborts.iter().any(|m| m.contains(
            "output still enabled after the output disable: running the last resort `touch"
        )),
        "{aborts:?}"
    );
    assert!(aborts.iter().any(|m| m.ends_with("done")), "{aborts:?}");
    assert!(marker.exists(), "the last resort ran");
}

#[test]
fn dc_sim_run_stage_ignoring_the_disable_without_a_last_resort_reports_it_unsafe() {
    let r = run(
        DC,
        "[[fault]]\nkind = \"ignore_disable\"\nat_s = 0\n\
         [[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"armature_current\"\n",
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    let stop = r.stop();
    assert!(stop.contains("SAFE-STATE COMMAND FAILED"), "{stop}");
    let aborts = r.events(EventLevel::Abort);
    assert!(
        aborts
            .iter()
            .any(|m| m.contains("THE STAGE MAY STILL BE DRIVING THE MACHINE")),
        "{aborts:?}"
    );
}

#[test]
fn dc_bad_fault_entries_are_refused_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    for (extra, key) in [
        (
            "[[fault]]\nkind = \"gremlins\"\nat_s = 1\n",
            "fault[0].kind",
        ),
        ("[[fault]]\nkind = \"nan\"\nat_s = 1\n", "fault[0].target"),
        (
            "[[fault]]\nkind = \"nan\"\nat_s = 1\ntarget = \"armature_current\"\n\
             [[fault]]\nkind = \"bus_timeout\"\nat_s = 1\ntarget = \"sensors\"\n",
            "fault[1].kind",
        ),
        (
            "[[fault]]\nkind = \"nan\"\nat_s = 1\nwhen = 2\n",
            "unknown field `when`",
        ),
    ] {
        let config = config_with(DC, "", extra, &[], dir.path());
        let out_dir = dir.path().join("out");
        let out = common::motorbench(&[
            "run",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
        ]);
        let (_, stderr) = common::text(&out);
        assert_eq!(out.status.code(), Some(2), "{stderr}");
        assert!(stderr.contains(key), "{key}: {stderr}");
    }
    // A target the rig does not have is refused when the rig is opened.
    let r = {
        let config = config_with(
            DC,
            "",
            "[[fault]]\nkind = \"nan\"\nat_s = 1\ntarget = \"torque\"\n",
            &[],
            dir.path(),
        );
        let out_dir = dir.path().join("out");
        common::motorbench(&[
            "run",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
        ])
    };
    let (_, stderr) = common::text(&r);
    assert_ne!(r.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("fault[0].target: the rig has no `torque` channel"),
        "{stderr}"
    );
}

// ---- DC, simulated rig served over Modbus TCP / RTU, `motorbench run` ----

const TCP: &str = "sim-modbus-dc.toml";
const RTU: &str = "sim-modbus-rtu-dc.toml";

/// A supervisor that waits out a retried call: a poll retried twice
/// (200 ms deadline each) delivers nothing for about 0.45 s.
const PATIENT: &str = "bus_loss_timeout_s = 1.5\nstale_timeout_s = 1.5";

#[test]
fn dc_tcp_run_short_sensor_timeout_is_retried() {
    let _one = realtime();
    let r = run_with(
        TCP,
        PATIENT,
        "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 0.15\ntarget = \"sensors\"\n",
        &[],
    );
    r.assert_retried();
}

#[test]
fn dc_tcp_run_long_sensor_timeout_aborts_safe() {
    let _one = realtime();
    let r = run(
        TCP,
        "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 30\ntarget = \"sensors\"\n",
    );
    r.assert_aborted_safe("device fault: sensor stream");
}

#[test]
fn dc_tcp_run_busy_exception_is_retried() {
    let _one = realtime();
    let r = run_with(
        TCP,
        PATIENT,
        "[[fault]]\nkind = \"modbus_exception\"\nat_s = 1.0\nfor_s = 0.02\ntarget = \"sensors\"\nvalue = 6\n",
        &[],
    );
    r.assert_retried();
}

#[test]
fn dc_tcp_run_device_failure_exception_aborts_safe() {
    let _one = realtime();
    let r = run(
        TCP,
        "[[fault]]\nkind = \"modbus_exception\"\nat_s = 1.0\ntarget = \"sensors\"\nvalue = 4\n",
    );
    r.assert_aborted_safe("device fault");
}

#[test]
fn dc_tcp_run_sensor_disconnect_aborts_safe() {
    let _one = realtime();
    let r = run(
        TCP,
        "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"sensors\"\n",
    );
    r.assert_aborted_safe("device fault: link to modbus-sensors failed");
}

#[test]
fn dc_tcp_run_stage_disconnect_aborts_and_reports_the_failed_safe_state() {
    let _one = realtime();
    let r = run(
        TCP,
        "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"power_stage\"\n",
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    let abort = r.plan_abort();
    assert!(abort.contains("power stage"), "{abort}");
    assert!(abort.contains("SAFE-STATE COMMAND FAILED"), "{abort}");
}

#[test]
fn dc_rtu_run_short_crc_errors_are_retried() {
    let _one = realtime();
    let r = run_with(
        RTU,
        PATIENT,
        "[[fault]]\nkind = \"crc_error\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"sensors\"\n",
        &[],
    );
    r.assert_retried();
}

#[test]
fn dc_rtu_run_short_garbage_is_skipped_by_the_decoder() {
    // Noise before a reply is skipped by the RTU decoder as it looks for
    // a frame: nothing is lost, nothing to retry.
    let _one = realtime();
    let r = run_with(
        RTU,
        PATIENT,
        "[[fault]]\nkind = \"garbage\"\nat_s = 1.0\nfor_s = 0.5\ntarget = \"sensors\"\n",
        &[],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(r.events(EventLevel::Abort).is_empty());
}

#[test]
fn dc_rtu_run_lasting_crc_errors_abort_safe() {
    let _one = realtime();
    let r = run(
        RTU,
        "[[fault]]\nkind = \"crc_error\"\nat_s = 1.0\ntarget = \"sensors\"\n",
    );
    r.assert_aborted_safe("device fault: sensor stream");
}

#[test]
fn dc_tcp_run_stage_ignoring_the_safe_command_is_disabled_over_modbus() {
    let _one = realtime();
    let r = run(
        TCP,
        "[[fault]]\nkind = \"ignore_safe_state\"\nat_s = 0\n\
         [[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"armature_current\"\n",
    );
    r.assert_aborted_safe("limit tripped: current NaN");
    assert_escalated_to_disable(&r.record);
}

#[test]
fn dc_tcp_run_stage_refusing_every_command_aborts_as_device_fault() {
    let _one = realtime();
    let r = run(
        TCP,
        "[[fault]]\nkind = \"modbus_exception\"\nat_s = 0\ntarget = \"power_stage\"\nvalue = 4\n",
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    // The plan's first command is refused; the plan hands the fault to
    // the supervisor, whose safe-state command is refused too: said so.
    let stop = r.stop();
    assert!(
        stop.starts_with("safety supervisor: device fault: power stage fault"),
        "{stop}"
    );
    assert!(stop.contains("SAFE-STATE COMMAND FAILED"), "{stop}");
}

#[test]
fn dc_rtu_run_sensor_disconnect_aborts_safe() {
    let _one = realtime();
    let r = run(
        RTU,
        "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"sensors\"\n",
    );
    // The served line's pseudo-terminal goes away with its server, as a
    // USB adapter pulled out: the port cannot be opened again.
    r.assert_aborted_safe("device fault: link to");
}

// ---- DC, a streaming serial DAQ beside a Modbus TCP supply ----

const SERIAL: &str = "sim-modbus-serial-dc.toml";

/// The binary framing (the shipped one) or the ASCII one.
const ASCII: (&str, &str) = ("framing = \"binary\"", "framing = \"ascii\"");
const ASCII_CHANNELS: (&str, &str) = (
    "channels = { armature_voltage = \"0\", armature_current = \"1\", encoder_count = \"2\" }",
    "channels = { armature_voltage = \"armature_voltage\", armature_current = \"armature_current\", encoder_count = \"encoder_count\" }",
);

#[test]
fn dc_serial_run_garbage_on_the_daq_stream_is_skipped_with_a_warning() {
    let _one = realtime();
    let r = run(
        SERIAL,
        "[[fault]]\nkind = \"garbage\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"sensors\"\n",
    );
    r.assert_degraded("garbage on the line");
}

#[test]
fn dc_serial_run_ascii_checksum_errors_on_the_daq_stream_are_refused_with_a_warning() {
    let _one = realtime();
    let r = run_with(
        SERIAL,
        "",
        "[[fault]]\nkind = \"crc_error\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"sensors\"\n",
        &[ASCII, ASCII_CHANNELS],
    );
    r.assert_degraded("frame(s) refused");
}

#[test]
fn dc_serial_run_daq_stream_hang_up_aborts_safe() {
    let _one = realtime();
    let r = run(
        SERIAL,
        "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"sensors\"\n",
    );
    r.assert_aborted_safe("device fault: serial:");
    assert!(r.stop().contains("sample stream ended"), "{}", r.stop());
}

#[test]
fn dc_serial_run_silent_daq_stream_aborts_safe() {
    let _one = realtime();
    let r = run(
        SERIAL,
        "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 5\ntarget = \"sensors\"\n",
    );
    r.assert_aborted_safe("device fault: sensor stream serial:");
    assert!(r.stop().contains("delivered nothing"), "{}", r.stop());
}

/// The supply over Modbus TCP, the DAQ streaming on a serial line and a
/// CANopen encoder behind an SLCAN adapter, all served.
const CAN: &str = "sim-modbus-can-dc.toml";

#[test]
fn dc_can_run_garbage_on_the_encoder_line_is_skipped_with_a_warning() {
    let _one = realtime();
    let r = run(
        CAN,
        "[[fault]]\nkind = \"garbage\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"encoder\"\n",
    );
    r.assert_degraded("garbage on the line");
    let warnings = r.events(EventLevel::Warn);
    assert!(
        warnings
            .iter()
            .any(|w| w.starts_with("slcan:") && w.contains("line(s) refused so far")),
        "{warnings:?}"
    );
}

#[test]
fn dc_can_run_encoder_adapter_hang_up_aborts_safe() {
    let _one = realtime();
    let r = run(
        CAN,
        "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"encoder\"\n",
    );
    r.assert_aborted_safe("device fault: slcan:");
}

#[test]
fn dc_can_run_silent_encoder_aborts_safe() {
    let _one = realtime();
    let r = run(
        CAN,
        "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 5\ntarget = \"encoder\"\n",
    );
    r.assert_aborted_safe("stale data: no new encoder_count reading");
}

// ---- induction machine, `motorbench run` ----

const IM: &str = "sim-im.toml";
const IM_TCP: &str = "sim-modbus-im.toml";

/// The shipped Modbus sweep cut to 6 points, for the rows whose fault
/// comes and goes in the first seconds: the retry is what they test, and
/// the sweep's other 10 points would only add half a minute of wall clock
/// (the served rig runs in real time).
const IM_TCP_SHORT: (&str, &str) = ("points = 16 ", "points = 6 ");

#[test]
fn im_sim_run_nan_line_current_aborts_safe() {
    let r = run(
        IM,
        "[[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"line_current\"\n",
    );
    r.assert_aborted_safe("limit tripped: current NaN");
}

#[test]
fn im_sim_run_clock_jump_aborts_safe() {
    let r = run(
        IM,
        "[[fault]]\nkind = \"clock_jump\"\nat_s = 1.0\nvalue = -0.2\n",
    );
    r.assert_aborted_safe("clock jump");
}

#[test]
fn im_sim_run_encoder_losing_half_its_counts_warns_against_the_dynamometer() {
    // The slips come from the encoder: reading half the speed, every
    // point would have a slip past one half, with nothing else to show
    // it; the dynamometer's speed does.
    let r = run(
        IM,
        "[[fault]]\nkind = \"encoder_loses_counts\"\nat_s = 0\nvalue = 0.5\n",
    );
    r.assert_warned("where the dynamometer holds");
    // No circuit follows slips of past one half: the fit collapses, and
    // the run says so (exit 4, nothing identified) rather than report a
    // circuit that misses the readings several times over.
    assert_eq!(r.code, Some(4), "{}", r.stderr);
    assert!(
        r.stderr
            .contains("no identification method applies to this data"),
        "{}",
        r.stderr
    );
    let result = r.record.recorded_result.as_ref().unwrap();
    let lm = &result["methods"]["lm"];
    assert_eq!(lm["applies"], false, "{lm}");
    assert!(
        lm["reason"]
            .as_str()
            .is_some_and(|t| t.contains("collapsed") && t.contains("Check that the columns")),
        "{lm}"
    );
    let warned: Vec<&str> = r
        .events(EventLevel::Warn)
        .into_iter()
        .filter(|w| w.contains("where the dynamometer holds"))
        .collect();
    assert_eq!(warned.len(), 1, "warned once a test: {warned:?}");
    assert!(
        warned[0].contains("0.50 times it") && warned[0].contains("16384 counts per revolution"),
        "{warned:?}"
    );
    // And `run` says so while the test runs.
    assert!(
        r.stderr.contains("motorbench: warning at test time ")
            && r.stderr.contains("where the dynamometer holds"),
        "{}",
        r.stderr
    );
}

#[test]
fn im_sim_run_supply_ignoring_the_safe_command_is_disabled() {
    let r = run(
        IM,
        "[[fault]]\nkind = \"ignore_safe_state\"\nat_s = 0\ntarget = \"supply\"\n\
         [[fault]]\nkind = \"inf\"\nat_s = 1.0\ntarget = \"line_voltage\"\n",
    );
    r.assert_aborted_safe("limit tripped: voltage inf");
    assert_escalated_to_disable(&r.record);
}

#[test]
fn im_tcp_run_short_meter_timeout_is_retried() {
    let _one = realtime();
    let r = run_with(
        IM_TCP,
        PATIENT,
        "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 0.15\ntarget = \"meter\"\n",
        &[IM_TCP_SHORT],
    );
    r.assert_retried();
}

#[test]
fn im_tcp_run_supply_ignoring_the_safe_command_is_disabled_over_modbus() {
    let _one = realtime();
    let r = run(
        IM_TCP,
        "[[fault]]\nkind = \"ignore_safe_state\"\nat_s = 0\ntarget = \"supply\"\n\
         [[fault]]\nkind = \"inf\"\nat_s = 1.0\ntarget = \"line_voltage\"\n",
    );
    r.assert_aborted_safe("limit tripped: voltage inf");
    // The VFD's control word read back still says run after the ignored
    // safe command: the supervisor disables the output over Modbus.
    assert_escalated_to_disable(&r.record);
}

#[test]
fn im_tcp_run_encoder_disconnect_aborts_safe() {
    let _one = realtime();
    let r = run(
        IM_TCP,
        "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"encoder\"\n",
    );
    r.assert_aborted_safe("device fault");
}

#[test]
fn im_tcp_run_meter_device_failure_exception_aborts_safe() {
    let _one = realtime();
    let r = run(
        IM_TCP,
        "[[fault]]\nkind = \"modbus_exception\"\nat_s = 1.0\ntarget = \"meter\"\nvalue = 4\n",
    );
    r.assert_aborted_safe("device fault");
}

#[test]
fn im_rtu_run_short_crc_errors_on_the_encoder_are_retried() {
    let _one = realtime();
    let r = run_with(
        IM_TCP,
        PATIENT,
        "[[fault]]\nkind = \"crc_error\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"encoder\"\n",
        &[("simulate = \"tcp\"", "simulate = \"rtu\""), IM_TCP_SHORT],
    );
    r.assert_retried();
}

#[test]
fn im_current_limit_is_refused_naming_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let config = config_with(
        IM,
        "",
        "[[fault]]\nkind = \"current_limit\"\nat_s = 0\nvalue = 1\n",
        &[],
        dir.path(),
    );
    let out = common::motorbench(&["run", "--config", config.to_str().unwrap()]);
    let (_, stderr) = common::text(&out);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("fault[0].kind: a current_limit fault needs"),
        "{stderr}"
    );
}

// ---- the daemon: `motorbench serve`, tests started through the API ----

mod daemon {
    use super::*;
    use crate::common::daemon::{finished, get, wait_test, Served};
    use serde_json::{json, Value};

    /// A daemon on `shipped` with `supervisor` keys and `faults`, one
    /// test started through the API (with `test` overriding `[test]`)
    /// and run to its end: the daemon, its client, the test's status and
    /// its record.
    async fn daemon_test(
        shipped: &str,
        supervisor: &str,
        faults: &str,
        test: Option<Value>,
    ) -> (
        Served,
        motorbench::serve::client::Client,
        Value,
        Record,
        tempfile::TempDir,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let config = config_with(shipped, supervisor, faults, &[], dir.path());
        let records = dir.path().join("records");
        let served = Served::start(&config, &records, dir.path(), &["--listen", "127.0.0.1:0"]);
        let c = served.client(None);
        let body = test.map(|t| json!({ "test": t }));
        let r = c.post("/v1/rigs/rig/tests", body.as_ref()).await.unwrap();
        assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
        let id = r.json()["id"].as_str().unwrap().to_string();
        let s = wait_test(&c, &id, finished).await;
        let record = read_mcap(&records.join(format!("{id}.mcap"))).unwrap();
        (served, c, s, record, dir)
    }

    /// The rig is latched (`tripped`), refuses a new test, and is free
    /// again after `ctl reset`.
    async fn assert_latched_until_reset(served: &Served, c: &motorbench::serve::client::Client) {
        assert_eq!(get(c, "/v1/rigs/rig").await["state"], "tripped");
        let refused = c.post("/v1/rigs/rig/tests", None).await.unwrap();
        assert_eq!(refused.status, 409);
        assert_eq!(refused.json()["error"], "tripped");
        let out = served.ctl(&["reset"]);
        assert!(out.status.success(), "{:?}", common::text(&out));
        assert_eq!(get(c, "/v1/rigs/rig").await["state"], "idle");
    }

    /// The test aborted for a stop of `kind`, its safe state reached
    /// (`safe`) or not, and the rig latched until reset.
    async fn assert_aborted_and_latched(
        served: &Served,
        c: &motorbench::serve::client::Client,
        s: &Value,
        kind: &str,
        safe: bool,
    ) {
        assert_eq!(s["outcome"], "aborted", "{s}");
        assert_eq!(s["stop"]["kind"], kind, "{s}");
        assert_eq!(s["stop"]["safe_state_ok"], safe, "{s}");
        assert_latched_until_reset(served, c).await;
    }

    /// The test completed after a link's retries, the rig idle again.
    async fn assert_completed_retried(
        c: &motorbench::serve::client::Client,
        s: &Value,
        record: &Record,
    ) {
        assert_eq!(s["outcome"], "completed", "{s}");
        assert_link_retried(record);
        assert_eq!(get(c, "/v1/rigs/rig").await["state"], "idle");
    }

    fn aborts(record: &Record) -> Vec<&str> {
        events(record, EventLevel::Abort)
    }

    const SHORT: fn() -> Option<Value> =
        || Some(json!({"levels_V": [60, 248, 60], "coastdown": false}));

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_daemon_nan_current_aborts_safe_and_latches() {
        let (served, c, s, _record, _dir) = daemon_test(
            DC,
            "",
            "[[fault]]\nkind = \"nan\"\nat_s = 0.5\ntarget = \"armature_current\"\n",
            SHORT(),
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "limit", true).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_daemon_clock_jump_aborts_safe_and_latches() {
        let (served, c, s, _record, _dir) = daemon_test(
            DC,
            "",
            "[[fault]]\nkind = \"clock_jump\"\nat_s = 0.5\nvalue = -0.1\n",
            SHORT(),
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "clock_jump", true).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_daemon_stage_ignoring_the_disable_gets_the_last_resort_and_latches() {
        let marker = tempfile::tempdir().unwrap();
        let touched = marker.path().join("contactor-opened");
        let (served, c, s, record, _dir) = daemon_test(
            DC,
            &format!("last_resort_command = [\"touch\", \"{}\"]", touched.display()),
            "[[fault]]\nkind = \"ignore_disable\"\nat_s = 0\n\
             [[fault]]\nkind = \"spike\"\nat_s = 0.5\ntarget = \"armature_voltage\"\nvalue = 1000\n",
            SHORT(),
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "limit", true).await;
        let aborts = aborts(&record);
        assert!(
            aborts
                .iter()
                .any(|m| m.contains("running the last resort `touch")),
            "{aborts:?}"
        );
        assert!(touched.exists(), "the last resort ran");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_daemon_stuck_sensor_warns_and_completes() {
        let (_served, _c, s, record, _dir) = daemon_test(
            DC,
            "stuck_after_s = 0.5",
            "[[fault]]\nkind = \"stuck\"\nat_s = 0.3\ntarget = \"armature_voltage\"\n",
            SHORT(),
        )
        .await;
        assert_eq!(s["outcome"], "completed", "{s}");
        assert!(
            record
                .events
                .iter()
                .any(|(_, e)| e.level == EventLevel::Warn
                    && e.message.contains("stuck sensor? `armature_voltage`")),
            "{:?}",
            record.events
        );
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_tcp_daemon_stage_refusing_commands_latches_as_device_fault() {
        let _one = REALTIME.lock().await;
        let (served, c, s, _record, _dir) = daemon_test(
            TCP,
            "",
            "[[fault]]\nkind = \"modbus_exception\"\nat_s = 0\ntarget = \"power_stage\"\nvalue = 4\n",
            None,
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "device_fault", false).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_tcp_daemon_sensor_disconnect_aborts_safe_and_latches() {
        let _one = REALTIME.lock().await;
        let (served, c, s, _record, _dir) = daemon_test(
            TCP,
            "",
            "[[fault]]\nkind = \"disconnect\"\nat_s = 1.0\ntarget = \"sensors\"\n",
            None,
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "device_fault", true).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn im_daemon_nan_line_current_aborts_safe_and_latches() {
        let (served, c, s, _record, _dir) = daemon_test(
            IM,
            "",
            "[[fault]]\nkind = \"nan\"\nat_s = 1.0\ntarget = \"line_current\"\n",
            None,
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "limit", true).await;
    }
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_tcp_daemon_short_sensor_timeout_is_retried() {
        let _one = REALTIME.lock().await;
        let (_served, c, s, record, _dir) = daemon_test(
            TCP,
            PATIENT,
            "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 0.15\ntarget = \"sensors\"\n",
            None,
        )
        .await;
        assert_completed_retried(&c, &s, &record).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_serial_daemon_garbage_on_the_daq_stream_completes_with_a_warning() {
        let _one = REALTIME.lock().await;
        let (_served, c, s, record, _dir) = daemon_test(
            SERIAL,
            "",
            "[[fault]]\nkind = \"garbage\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"sensors\"\n",
            None,
        )
        .await;
        assert_eq!(s["outcome"], "completed", "{s}");
        let warnings = events(&record, EventLevel::Warn);
        assert!(
            warnings.iter().any(|w| w.contains("garbage on the line")),
            "{warnings:?}"
        );
        assert_eq!(get(&c, "/v1/rigs/rig").await["state"], "idle");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_can_daemon_silent_encoder_aborts_safe_and_latches() {
        let _one = REALTIME.lock().await;
        let (served, c, s, _record, _dir) = daemon_test(
            CAN,
            "",
            "[[fault]]\nkind = \"bus_timeout\"\nat_s = 1.0\nfor_s = 5\ntarget = \"encoder\"\n",
            None,
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "stale_channel", true).await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn im_daemon_supply_ignoring_the_safe_command_is_disabled_and_latches() {
        let (served, c, s, record, _dir) = daemon_test(
            IM,
            "",
            "[[fault]]\nkind = \"ignore_safe_state\"\nat_s = 0\ntarget = \"supply\"\n\
             [[fault]]\nkind = \"spike\"\nat_s = 1.0\ntarget = \"line_current\"\nvalue = 1000\n",
            None,
        )
        .await;
        assert_aborted_and_latched(&served, &c, &s, "limit", true).await;
        let aborts = aborts(&record);
        assert!(
            aborts.iter().any(|m| m.ends_with("output disabled")),
            "{aborts:?}"
        );
    }
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn dc_rtu_daemon_short_crc_errors_are_retried() {
        let _one = REALTIME.lock().await;
        let (_served, c, s, record, _dir) = daemon_test(
            RTU,
            PATIENT,
            "[[fault]]\nkind = \"crc_error\"\nat_s = 1.0\nfor_s = 0.1\ntarget = \"sensors\"\n",
            None,
        )
        .await;
        assert_completed_retried(&c, &s, &record).await;
    }
}
