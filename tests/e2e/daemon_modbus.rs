//! End to end: the `motorbench serve` binary on the simulated rig behind
//! Modbus TCP, driven through its HTTP API and `motorbench ctl`.
//!
//! Two ways of serving the rig:
//! - `config/sim-modbus-dc.toml` as shipped: the daemon serves the
//!   simulated supply and DAQ itself (`rig.modbus.simulate = "tcp"`) and
//!   reaches them through the real Modbus client; a short DC test runs to
//!   completion through `ctl start --follow`.
//! - The same rig served by this test process, and the daemon given a
//!   configuration with their TCP addresses (as for hardware): the daemon
//!   cannot tell it from a real supply. This is where an abort halfway is
//!   timed from the API call to the moment the served supply's registers
//!   show the output off (the Modbus write has arrived), on the test
//!   process's clock. The figure is printed, not asserted (run with
//!   `--nocapture`).
//!
//! The same rig again with the DAQ reached through a pymodbus proxy
//! (`tests/python/modbus_fault_proxy.py`) that, on command, leaves
//! requests unanswered or answers "device busy": `/metrics` (parsed by
//! the Prometheus client library) counts exactly those timeouts and
//! exceptions, with their retries and reconnections, on the DAQ's bus
//! and none on the supply's, live while the test runs.
//!
//! And one daemon with two rigs behind Modbus: the DC rig of
//! `config/sim-modbus-dc.toml` (served by the daemon) and the induction-
//! machine rig of `config/sim-modbus-im.toml` served by this test process
//! (supply VFD, dynamometer VFD, meter, encoder counter, each its own
//! Modbus TCP server). A DC test runs to completion through `ctl` while an
//! IM slip sweep runs through the API with its progress on the live feed;
//! the sweep is aborted halfway and both stages are seen safe at their
//! registers (supply: run off, frequency 0; dynamometer: stop, frequency
//! 0), timed from the API call.

use crate::common;

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use motorbench::config::{Backend, Config};
use motorbench::machine::dc::build_rig;
use motorbench::machine::im::{build_im_rig, ImRunConfig};
use motorbench::record::{read_mcap, EventLevel};
use motorbench::rig::ServedLink;
use motorbench_drivers::modbus::server::lock_bank;

use common::daemon::{get, shipped, wait_test, Metrics, Served, PATIENCE};
use common::peer::Peer;

/// Held by every wall-clock test of this file: they run one after the
/// other so that they do not disturb each other's sampling.
static REALTIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Start a test on `rig` through the API (with `test` over its
/// configured plan); its id.
async fn start_test(served: &Served, rig: &str, test: Option<&serde_json::Value>) -> String {
    let r = served
        .client(None)
        .post(&format!("/v1/rigs/{rig}/tests"), test)
        .await
        .unwrap();
    assert_eq!(
        r.status,
        201,
        "{}\n{}",
        String::from_utf8_lossy(&r.body),
        served.log()
    );
    r.json()["id"].as_str().unwrap().to_string()
}

/// Start the daemon on `config`, records and log in `dir`.
fn start_daemon(config: &Path, dir: &Path) -> Served {
    Served::start(
        config,
        &dir.join("records"),
        dir,
        &["--listen", "127.0.0.1:0"],
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn shipped_modbus_config_runs_a_dc_test_through_the_api() {
    let _one_at_a_time = REALTIME.lock().await;
    let dir = tempfile::tempdir().unwrap();
    let served = start_daemon(&shipped("sim-modbus-dc.toml"), dir.path());
    let c = served.client(None);

    let rigs = get(&c, "/v1/rigs").await;
    assert_eq!(rigs["rigs"][0]["state"], "idle", "{rigs}");

    let out = served.ctl(&[
        "start",
        "--test-json",
        r#"{"levels_V": [10, 55], "coastdown": false}"#,
        "--follow",
    ]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}\n{}", served.log());
    let id = stdout.lines().next().unwrap().trim().to_string();
    assert!(stdout.contains(&format!("{id}: completed")), "{stdout}");
    assert!(
        stdout.contains("segment 2/2"),
        "progress was shown: {stdout}"
    );

    let entry = get(&c, &format!("/v1/records/{id}")).await;
    assert_eq!(entry["outcome"], "completed");
    assert_eq!(entry["motor_id"], "seed-table4-dc");
    let ra = entry["key_results"]["params"]["Ra"].as_f64().unwrap();
    assert!((ra / 30.9 - 1.0).abs() < 0.10, "Ra {ra}");

    // The record replays to the recorded result.
    let mcap = dir.path().join("records").join(format!("{id}.mcap"));
    let replay = common::motorbench(&["replay", mcap.to_str().unwrap(), "--check"]);
    let (_, replay_err) = common::text(&replay);
    assert!(replay.status.success(), "{replay_err}");
    assert!(replay_err.contains("identical"), "{replay_err}");

    // The supervisor relays the Modbus poller's statistics: the record
    // holds one sampling-statistics event per polled channel.
    let rec = read_mcap(&mcap).unwrap();
    let stats: Vec<&str> = rec
        .events
        .iter()
        .filter(|(_, e)| e.message.starts_with("sampling statistics"))
        .map(|(_, e)| e.message.as_str())
        .collect();
    for q in ["armature_voltage", "armature_current", "encoder_count"] {
        assert!(stats.iter().any(|m| m.contains(q)), "{q}: {stats:?}");
    }
}

/// `config/sim-modbus-dc.toml` rewritten for a rig reached at `stage` and
/// `daq` (no `simulate`, no `[rig.simulated]`: to the daemon it is
/// hardware), with the profiles' paths made absolute.
fn hardware_config(stage: &ServedLink, daq: &ServedLink) -> String {
    let addr = |l: &ServedLink| match l {
        ServedLink::Tcp(a) => a.to_string(),
        other => panic!("served over TCP, not {other:?}"),
    };
    let text = std::fs::read_to_string(shipped("sim-modbus-dc.toml")).unwrap();
    let devices = shipped("devices");
    let cut = text.find("[rig.simulated.motor]").unwrap();
    let limits = text.find("[limits]").unwrap();
    let text = format!("{}{}", &text[..cut], &text[limits..]);
    let mut out = String::new();
    let mut section = "";
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            section = if trimmed.starts_with("[rig.modbus.power_stage]") {
                "stage"
            } else if trimmed.starts_with("[rig.modbus.sensors]") {
                "daq"
            } else {
                ""
            };
        }
        if trimmed.starts_with("simulate =") {
            continue;
        }
        if let Some(rest) = trimmed.strip_prefix("profile = \"devices/") {
            let file = rest.split('"').next().unwrap();
            out.push_str(&format!(
                "profile = {:?}\n",
                devices.join(file).to_str().unwrap()
            ));
            let link = if section == "stage" { stage } else { daq };
            out.push_str(&format!(
                "transport = \"tcp\"\naddress = \"{}\"\n",
                addr(link)
            ));
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn abort_halfway_behind_modbus_makes_the_supply_safe_and_is_timed() {
    let _one_at_a_time = REALTIME.lock().await;
    // Serve the simulated rig from this process (its Modbus TCP servers on
    // loopback), keeping only the servers.
    let shipped_cfg = Config::load(&shipped("sim-modbus-dc.toml")).unwrap();
    let profile = match &shipped_cfg.backend {
        Backend::Modbus { rig, .. } => rig.power_stage.profile.clone(),
        _ => unreachable!("the shipped configuration is a Modbus rig"),
    };
    let rig = build_rig(&shipped_cfg, false).await.unwrap();
    let mut rig = rig;
    let rig_served = rig.served.take().expect("a served rig");
    drop(rig);
    let output_enable = profile.register("output_enable").unwrap().clone();
    let voltage_set = profile.register("voltage_set").unwrap().clone();

    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("rig.toml");
    std::fs::write(
        &config,
        hardware_config(&rig_served.stage_link, &rig_served.daq_link),
    )
    .unwrap();
    let daemon_view = Config::load(&config).unwrap();
    assert!(daemon_view.backend.simulated().is_none(), "hardware to it");
    let served = start_daemon(&config, dir.path());
    let c = served.client(None);

    // The full staircase; abort it halfway.
    let id = start_test(&served, "rig", None).await;
    let s = wait_test(&c, &id, |s| {
        s["segment"]["index"].as_u64().unwrap_or(0) * 2
            >= s["segment"]["total"].as_u64().unwrap_or(99)
    })
    .await;
    assert!(s["values"]["current"].is_number(), "{s}");
    {
        let bank = lock_bank(&rig_served.stage_bank);
        assert_eq!(bank.get(&output_enable), 1.0, "the output is on mid-test");
        assert!(bank.get(&voltage_set) > 0.0, "a level is set mid-test");
    }

    // Watch the supply's registers on a thread of its own while the abort
    // goes out: the instants its output-enable and set-point registers are
    // written to zero, on the same clock as the request.
    let bank = rig_served.stage_bank.clone();
    let armed = Arc::new(AtomicBool::new(true));
    let watching = armed.clone();
    let watcher = std::thread::spawn(move || {
        let (mut off, mut zero) = (None, None);
        let t0 = Instant::now();
        while watching.load(Ordering::Relaxed) && (off.is_none() || zero.is_none()) {
            {
                let b = lock_bank(&bank);
                if off.is_none() && b.get(&output_enable) == 0.0 {
                    off = Some(Instant::now());
                }
                if zero.is_none() && b.get(&voltage_set) == 0.0 {
                    zero = Some(Instant::now());
                }
            }
            if t0.elapsed() > PATIENCE {
                break;
            }
            std::thread::sleep(Duration::from_micros(20));
        }
        (off, zero)
    });
    let sent = Instant::now();
    let r = c
        .post(&format!("/v1/tests/{id}/abort"), None)
        .await
        .unwrap();
    let answered = Instant::now();
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let stop = r.json()["stop"].clone();
    assert_eq!(stop["kind"], "operator_abort");
    assert_eq!(stop["safe_state_ok"], true);
    // The daemon answers after it has commanded the safe state, so the
    // registers are already written; the watcher only has to notice.
    let watched = tokio::task::spawn_blocking(move || {
        let deadline = Instant::now() + Duration::from_secs(5);
        while !watcher.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
        armed.store(false, Ordering::Relaxed);
        watcher.join().unwrap()
    })
    .await
    .unwrap();
    let (Some(off), Some(zero)) = watched else {
        panic!("the supply's registers never showed it safe: {watched:?}");
    };
    assert!(
        off >= sent && zero >= sent,
        "it was on when the abort went out"
    );

    let s = wait_test(&c, &id, |s| s["state"] == "finished").await;
    assert_eq!(s["outcome"], "aborted");
    let stop = &s["stop"];
    let requested = stop["requested_t_s"].as_f64().unwrap();
    let first_safe = stop["first_safe_sample_t_s"]
        .as_f64()
        .expect("a sample after the safe state");
    let period = 1.0 / 200.0;

    // The supply stays safe, and the record tells the story.
    {
        let b = lock_bank(&rig_served.stage_bank);
        let p = &profile;
        assert_eq!(b.get(p.register("output_enable").unwrap()), 0.0);
        assert_eq!(b.get(p.register("voltage_set").unwrap()), 0.0);
    }
    assert!(!rig_served.stage_output_enabled());
    let rec = read_mcap(&dir.path().join("records").join(format!("{id}.mcap"))).unwrap();
    assert!(rec.recovery.is_none(), "the record was finished");
    let abort = rec
        .events
        .iter()
        .find(|(_, e)| e.level == EventLevel::Abort)
        .expect("an abort event");
    assert!(
        abort.1.message.contains("operator abort"),
        "{}",
        abort.1.message
    );
    let entry = get(&c, &format!("/v1/records/{id}")).await;
    assert_eq!(entry["outcome"], "aborted");

    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "ABORT LATENCY BEHIND MODBUS TCP: API call → supply output-enable register off {:.3} ms, \
         → voltage set point register 0 {:.3} ms (test-process clock, includes the HTTP request, \
         the daemon and the Modbus write round trip); abort HTTP round trip {:.3} ms; \
         daemon side: request received → safe-state command returned {:.3} ms; \
         sample period {:.1} ms; last sample before the request at {requested:.4} s, \
         first sample read after the safe state at {first_safe:.4} s ({:.1} sample periods)",
        ms(off - sent),
        ms(zero - sent),
        ms(answered - sent),
        stop["safe_after_s"].as_f64().unwrap() * 1e3,
        period * 1e3,
        (first_safe - requested) / period,
    );
}

/// Read the fault proxy's lines until it has said `INJECTED <kind> <n>`
/// for each of `faults`.
fn wait_injected(proxy: &mut Peer, faults: &[(&str, u64)]) {
    let mut waiting: Vec<String> = faults
        .iter()
        .map(|(kind, n)| format!("INJECTED {kind} {n}"))
        .collect();
    while !waiting.is_empty() {
        let line = tokio::task::block_in_place(|| proxy.line());
        waiting.retain(|w| *w != line);
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bus_timeouts_and_exceptions_from_a_pymodbus_peer_are_counted_per_bus_in_the_metrics() {
    let _one_at_a_time = REALTIME.lock().await;
    let shipped_cfg = Config::load(&shipped("sim-modbus-dc.toml")).unwrap();
    let mut rig = build_rig(&shipped_cfg, false).await.unwrap();
    let rig_served = rig.served.take().expect("a served rig");
    drop(rig);
    let ServedLink::Tcp(daq) = rig_served.daq_link.clone() else {
        panic!("the DAQ is served over TCP");
    };
    let ServedLink::Tcp(stage) = rig_served.stage_link.clone() else {
        panic!("the supply is served over TCP");
    };
    let mut proxy = Peer::start(
        "modbus_fault_proxy.py",
        &[&daq.ip().to_string(), &daq.port().to_string()],
    );
    let proxied: std::net::SocketAddr = format!("127.0.0.1:{}", proxy.ready()).parse().unwrap();

    // The daemon reaches the DAQ through the proxy. A timed-out poll and
    // its retry leave the channels silent for about 0.2 s: more than the
    // default stale-data timeout, so this rig allows 1 s.
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("rig.toml");
    let text = hardware_config(&rig_served.stage_link, &ServedLink::Tcp(proxied));
    let text = text.replace(
        "bus_loss_timeout_s = 1.0",
        "bus_loss_timeout_s = 1.0\nstale_timeout_s = 1.0",
    );
    assert!(text.contains("stale_timeout_s = 1.0"), "{text}");
    std::fs::write(&config, text).unwrap();
    let served = start_daemon(&config, dir.path());
    let c = served.client(None);
    let (daq_bus, stage_bus) = (format!("tcp:{proxied}"), format!("tcp:{stage}"));

    let levels =
        serde_json::json!({"test": {"levels_V": [10, 55, 10, 32, 55, 21], "coastdown": false}});
    let id = start_test(&served, "rig", Some(&levels)).await;
    wait_test(&c, &id, |s| s["t_s"].as_f64().unwrap_or(0.0) > 0.5).await;

    // Live, before any fault: both buses carry requests, the recorder's
    // queue is shown and within its capacity.
    let before = Metrics::scrape(&c, dir.path()).await;
    let rig = ("rig", "rig");
    fn bus(b: &str) -> [(&str, &str); 2] {
        [("rig", "rig"), ("bus", b)]
    }
    for b in [&daq_bus, &stage_bus] {
        assert!(
            before.value("bus_requests_total", &bus(b)) > 0.0,
            "{b}: {:?}",
            before.0
        );
    }
    assert_eq!(before.count("recorder_backlog", &[rig]), 1);
    let backlog = before.value("recorder_backlog", &[rig]);
    assert!((0.0..=4096.0).contains(&backlog), "backlog {backlog}");

    let errors = |m: &Metrics, b: &str, kind: &str| {
        m.value("bus_errors_total", &[rig, ("bus", b), ("kind", kind)])
    };
    proxy.send("timeout 2");
    proxy.send("busy 3");
    wait_injected(&mut proxy, &[("timeout", 2), ("busy", 3)]);
    // Each fault is counted once its call has ended (after the retry the
    // proxy lets through): scrape until both show, then they must be
    // exactly what was injected.
    let t0 = Instant::now();
    let during = loop {
        let m = Metrics::scrape(&c, dir.path()).await;
        let grown = |kind| errors(&m, &daq_bus, kind) - errors(&before, &daq_bus, kind);
        if grown("timeout") >= 2.0 && grown("exception") >= 3.0 {
            break m;
        }
        assert!(
            t0.elapsed() < PATIENCE,
            "the faults never showed: {:?}",
            m.0
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    };
    let status = get(&c, &format!("/v1/tests/{id}")).await;
    println!(
        "faults counted while the test was {}",
        status["state"].as_str().unwrap_or("?")
    );
    for (kind, n) in ["timeout", "exception", "retry", "reconnect", "link_error"]
        .iter()
        .map(|k| (k, errors(&during, &daq_bus, k)))
    {
        println!(
            "motorbench_bus_errors_total{{rig=\"rig\",bus=\"{daq_bus}\",kind=\"{kind}\"}} {n}"
        );
    }
    let grown = |kind| errors(&during, &daq_bus, kind) - errors(&before, &daq_bus, kind);
    assert_eq!(grown("timeout"), 2.0, "{:?}", during.0);
    assert_eq!(grown("exception"), 3.0);
    // Every fault was retried once; each timeout dropped the connection,
    // which was opened again.
    assert_eq!(grown("retry"), 5.0);
    assert_eq!(grown("reconnect"), 2.0);
    assert_eq!(grown("link_error"), 0.0);
    for kind in ["timeout", "exception", "link_error", "retry", "reconnect"] {
        assert_eq!(errors(&during, &stage_bus, kind), 0.0, "supply {kind}");
    }

    // The test rode over the faults; what the metrics hold after its end
    // is at least what they showed live (counters never go back).
    let s = wait_test(&c, &id, |s| s["state"] == "finished").await;
    assert_eq!(s["outcome"], "completed", "{s}\n{}", served.log());
    let after = Metrics::scrape(&c, dir.path()).await;
    for kind in ["timeout", "exception", "retry", "reconnect"] {
        assert!(errors(&after, &daq_bus, kind) >= errors(&during, &daq_bus, kind));
    }
    assert!(
        after.value("bus_requests_total", &bus(&daq_bus))
            > during.value("bus_requests_total", &bus(&daq_bus))
    );
    assert_eq!(after.value("recorder_backlog", &[rig]), 0.0, "idle");
    proxy.close_stdin();
}

/// `config/sim-modbus-im.toml` rewritten for a rig reached at the served
/// IM rig's addresses (no `simulate`, no `[rig.simulated]`: hardware to
/// the daemon), with the profiles' paths made absolute.
fn im_hardware_config(served: &motorbench::machine::im::ServedImRig) -> String {
    let addr = |l: &ServedLink| match l {
        ServedLink::Tcp(a) => a.to_string(),
        other => panic!("served over TCP, not {other:?}"),
    };
    let text = std::fs::read_to_string(shipped("sim-modbus-im.toml")).unwrap();
    let devices = shipped("devices");
    let cut = text.find("[rig.simulated.motor]").unwrap();
    let limits = text.find("[limits]").unwrap();
    let text = format!("{}{}", &text[..cut], &text[limits..]);
    let mut out = String::new();
    let mut link = None;
    for line in text.lines() {
        let trimmed = line.trim_start();
        if trimmed.starts_with('[') {
            link = match trimmed {
                t if t.starts_with("[rig.modbus.supply]") => Some(&served.supply.link),
                t if t.starts_with("[rig.modbus.dynamometer]") => Some(&served.dynamometer.link),
                t if t.starts_with("[rig.modbus.meter]") => Some(&served.meter_link),
                t if t.starts_with("[rig.modbus.encoder]") => Some(&served.encoder_link),
                _ => None,
            };
        }
        if trimmed.starts_with("simulate =") {
            continue;
        }
        if let Some(rest) = trimmed.strip_prefix("profile = \"devices/") {
            let file = rest.split('"').next().unwrap();
            out.push_str(&format!(
                "profile = {:?}\n",
                devices.join(file).to_str().unwrap()
            ));
            out.push_str(&format!(
                "transport = \"tcp\"\naddress = \"{}\"\n",
                addr(link.expect("a device section"))
            ));
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    out
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn one_daemon_runs_a_dc_test_and_an_im_sweep_and_aborts_the_sweep_with_both_stages_safe() {
    let _one_at_a_time = REALTIME.lock().await;
    // The IM rig served from this process, keeping only its servers.
    let shipped_im = ImRunConfig::load(&shipped("sim-modbus-im.toml")).unwrap();
    let vfd = shipped_im.modbus.as_ref().unwrap().supply.profile.clone();
    let control = vfd.register("control_word").unwrap().clone();
    let frequency = vfd.register("frequency_set").unwrap().clone();
    let mut rig = build_im_rig(&shipped_im, false).await.unwrap();
    let im = rig.served.take().expect("a served rig");
    drop(rig);

    let dir = tempfile::tempdir().unwrap();
    let im_config = dir.path().join("im-rig.toml");
    std::fs::write(&im_config, im_hardware_config(&im)).unwrap();
    let daemon_view = ImRunConfig::load(&im_config).unwrap();
    assert!(daemon_view.simulated.is_none(), "hardware to it");
    let served = Served::start(
        &shipped("sim-modbus-dc.toml"),
        &dir.path().join("records"),
        dir.path(),
        &[
            "--listen",
            "127.0.0.1:0",
            "--config",
            im_config.to_str().unwrap(),
        ],
    );
    let c = served.client(None);
    let rigs = get(&c, "/v1/rigs").await;
    let rig_of = |name: &str| {
        rigs["rigs"]
            .as_array()
            .unwrap()
            .iter()
            .find(|r| r["name"] == name)
            .unwrap_or_else(|| panic!("rig {name} in {rigs}"))
            .clone()
    };
    let im_rig = rig_of("im-rig");
    assert_eq!(im_rig["machine"], "induction");
    assert_eq!(
        im_rig["stages"],
        serde_json::json!(["supply", "dynamometer"])
    );
    assert_eq!(rig_of("sim-modbus-dc")["machine"], "dc");

    // The full sweep on the IM rig, through the API.
    let sweep = start_test(&served, "im-rig", None).await;

    // Meanwhile a short DC test on the other rig, through `ctl`.
    let out = served.ctl(&[
        "start",
        "--rig",
        "sim-modbus-dc",
        "--test-json",
        r#"{"levels_V": [10, 55], "coastdown": false}"#,
        "--follow",
    ]);
    let (stdout, stderr) = common::text(&out);
    assert!(out.status.success(), "{stdout}\n{stderr}\n{}", served.log());
    let dc = stdout.lines().next().unwrap().trim().to_string();
    assert!(stdout.contains(&format!("{dc}: completed")), "{stdout}");
    let entry = get(&c, &format!("/v1/records/{dc}")).await;
    assert_eq!(entry["outcome"], "completed");
    let ra = entry["key_results"]["params"]["Ra"].as_f64().unwrap();
    assert!((ra / 30.9 - 1.0).abs() < 0.10, "Ra {ra}");

    // The sweep's live feed: its segment, and the meter's readings.
    let s = wait_test(&c, &sweep, |s| {
        s["t_s"].as_f64().unwrap_or(0.0) > 12.0
            && s["values"]["current"].as_f64().unwrap_or(0.0) > 0.0
    })
    .await;
    assert_eq!(s["state"], "running", "{s}");
    assert_eq!(s["segment"]["kind"], "im_slip_sweep", "{s}");
    assert!(
        s["plan"]
            .as_str()
            .unwrap()
            .starts_with("im_slip_sweep 400 V"),
        "{s}"
    );
    assert!(
        s["values"]["speed"].is_number(),
        "the encoder's speed is shown: {s}"
    );
    // The sweep's operating points on the live feed as they are
    // recorded; the metrics count requests on each of its four buses
    // (named by their configured addresses), each with its error counts.
    let s = wait_test(&c, &sweep, |s| {
        s["operating_points"]
            .as_array()
            .is_some_and(|p| !p.is_empty())
    })
    .await;
    let p = &s["operating_points"][0];
    assert_eq!(p["segment"], 0, "{p}");
    assert!((0.0..=1.0).contains(&p["slip"].as_f64().unwrap()), "{p}");
    assert!(p["line_current"].as_f64().unwrap() > 0.0, "{p}");
    let m = Metrics::scrape(&c, dir.path()).await;
    let links = [
        &im.supply.link,
        &im.dynamometer.link,
        &im.meter_link,
        &im.encoder_link,
    ];
    for link in links {
        let ServedLink::Tcp(a) = link else {
            panic!("served over TCP")
        };
        let bus = format!("tcp:{a}");
        let labels = [("rig", "im-rig"), ("bus", bus.as_str())];
        assert!(
            m.value("bus_requests_total", &labels) > 0.0,
            "{bus}: {:?}",
            m.0
        );
        let timeouts = [labels[0], labels[1], ("kind", "timeout")];
        assert_eq!(m.count("bus_errors_total", &timeouts), 1, "{bus}");
    }
    // Wait for a point with the supply on (not a cool-down), then abort.
    // The live feed's last sample and the supply's registers are read
    // together: a feed a poll behind may still show the voltage of a
    // point whose cool-down has begun.
    let s = wait_test(&c, &sweep, |s| {
        let b = lock_bank(&im.supply.bank);
        s["values"]["voltage"].as_f64().unwrap_or(0.0) > 300.0
            && b.get(&control) == 1.0
            && b.get(&frequency) == 50.0
    })
    .await;
    assert_eq!(s["state"], "running", "{s}");
    {
        let b = lock_bank(&im.supply.bank);
        assert_eq!(b.get(&control), 1.0, "the supply runs mid-sweep");
        assert_eq!(b.get(&frequency), 50.0);
        assert!(im.supply_output_enabled());
    }

    // Watch both drives' registers on a thread of their own while the
    // abort goes out.
    let (supply_bank, dyno_bank) = (im.supply.bank.clone(), im.dynamometer.bank.clone());
    let (ctl_reg, freq_reg) = (control.clone(), frequency.clone());
    let armed = Arc::new(AtomicBool::new(true));
    let watching = armed.clone();
    let watcher = std::thread::spawn(move || {
        let (mut supply_off, mut dyno_stop) = (None, None);
        let t0 = Instant::now();
        while watching.load(Ordering::Relaxed) && (supply_off.is_none() || dyno_stop.is_none()) {
            if supply_off.is_none() && lock_bank(&supply_bank).get(&ctl_reg) == 0.0 {
                supply_off = Some(Instant::now());
            }
            if dyno_stop.is_none() {
                let b = lock_bank(&dyno_bank);
                if b.get(&ctl_reg) == 0.0 && b.get(&freq_reg) == 0.0 {
                    dyno_stop = Some(Instant::now());
                }
            }
            if t0.elapsed() > PATIENCE {
                break;
            }
            std::thread::sleep(Duration::from_micros(20));
        }
        (supply_off, dyno_stop)
    });
    let sent = Instant::now();
    let r = c
        .post(&format!("/v1/tests/{sweep}/abort"), None)
        .await
        .unwrap();
    let answered = Instant::now();
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let stop = r.json()["stop"].clone();
    assert_eq!(stop["kind"], "operator_abort");
    assert_eq!(stop["safe_state_ok"], true, "{stop}");
    let watched = tokio::task::spawn_blocking(move || {
        let deadline = Instant::now() + Duration::from_secs(5);
        while !watcher.is_finished() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(1));
        }
        armed.store(false, Ordering::Relaxed);
        watcher.join().unwrap()
    })
    .await
    .unwrap();
    let (Some(supply_off), Some(dyno_stop)) = watched else {
        panic!("the drives' registers never showed both stages safe: {watched:?}");
    };
    assert!(supply_off >= sent && dyno_stop >= sent);

    let s = wait_test(&c, &sweep, |s| s["state"] == "finished").await;
    assert_eq!(s["outcome"], "aborted", "{s}");
    let requested = s["stop"]["requested_t_s"].as_f64().unwrap();
    let first_safe = s["stop"]["first_safe_sample_t_s"].as_f64();

    // Both stages stay safe: the supply off, the dynamometer braking the
    // shaft to rest.
    {
        let b = lock_bank(&im.supply.bank);
        assert_eq!((b.get(&control), b.get(&frequency)), (0.0, 0.0));
        let b = lock_bank(&im.dynamometer.bank);
        assert_eq!((b.get(&control), b.get(&frequency)), (0.0, 0.0));
    }
    assert!(!im.supply_output_enabled());
    assert_eq!(im.dyno_command(), (0.0, true));

    // The record: the supervisor's stop, the sweep's abort, the points
    // measured before it; the index says aborted; the rig is idle again
    // (an operator abort does not latch).
    let rec = read_mcap(&dir.path().join("records").join(format!("{sweep}.mcap"))).unwrap();
    assert!(rec.recovery.is_none(), "the record was finished");
    assert!(
        rec.events
            .iter()
            .any(|(_, e)| e.level == EventLevel::Abort && e.message.contains("operator abort")),
        "{:?}",
        rec.events
    );
    assert!(
        rec.events
            .iter()
            .any(|(_, e)| e.message.starts_with("safety supervisor: operator abort")),
        "{:?}",
        rec.events
    );
    assert!(!rec.operating_points.is_empty(), "points before the abort");
    let entry = get(&c, &format!("/v1/records/{sweep}")).await;
    assert_eq!(entry["outcome"], "aborted");
    assert_eq!(entry["kind"], "im_slip_sweep");
    let rigs = get(&c, "/v1/rigs").await;
    assert!(
        rigs["rigs"]
            .as_array()
            .unwrap()
            .iter()
            .all(|r| r["state"] == "idle"),
        "{rigs}"
    );

    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "IM ABORT LATENCY BEHIND MODBUS TCP: API call → supply VFD run bit off {:.3} ms, \
         → dynamometer VFD stopped (control word and frequency 0) {:.3} ms (test-process clock); \
         abort HTTP round trip {:.3} ms; daemon side: request → both safe-state commands returned \
         {:.3} ms; poll period 5 ms; last sample before the request at {requested:.4} s, first \
         sample after the safe state at {first_safe:?} s; {} operating points before the abort",
        ms(supply_off - sent),
        ms(dyno_stop - sent),
        ms(answered - sent),
        stop["safe_after_s"].as_f64().unwrap() * 1e3,
        rec.operating_points.len(),
    );
}
