//! End to end: the `motorbench serve` binary on the simulated rig (paced
//! at the wall clock), driven through its HTTP API and `motorbench ctl`.
//!
//! Covered: a DC test run through the API and fetched; one test at a time
//! (409 with the running id); an abort halfway with the rig safe and the
//! latency measured (printed, not asserted: run with `--nocapture`);
//! SIGKILL mid-test leaving a record that replays and is marked
//! interrupted on the next start; SIGTERM stopping a test safely with the
//! MCAP finished; the token off loopback; the Unix socket; emergency stop
//! and reset; a speed trip the sequencer sees first latching the rig.
//!
//! The simulated rig behind Modbus (and the abort timed at the supply's
//! registers) is in `tests/e2e/daemon_modbus.rs`.

use crate::common;

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use motorbench::record::{read_mcap, EventLevel};
use motorbench::serve::client::{Client, Reply};
use serde_json::{json, Value};

use common::daemon::{finished, get, wait_test, Served, BIN};

/// Start the daemon on the embedded default configuration (written to
/// `dir/rig.toml` unless a test put its own there).
fn start_daemon(dir: &Path, records: &Path, extra: &[&str]) -> Served {
    let config = dir.join("rig.toml");
    if !config.exists() {
        std::fs::write(&config, motorbench::config::DEFAULT_CONFIG).unwrap();
    }
    Served::start(&config, records, dir, extra)
}

async fn start(c: &Client, test: Option<Value>) -> Reply {
    let body = test.map(|t| json!({ "test": t }));
    c.post("/v1/rigs/rig/tests", body.as_ref()).await.unwrap()
}

async fn record_entry(c: &Client, name: &str) -> Value {
    get(c, &format!("/v1/records/{name}")).await
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn dc_test_through_the_api_one_at_a_time_and_abort_halfway() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);

    // A short DC staircase through `ctl start --follow`.
    let out = served.ctl(&[
        "start",
        "--test-json",
        r#"{"levels_V": [60, 248], "coastdown": false}"#,
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

    let entry = record_entry(&c, &id).await;
    assert_eq!(entry["outcome"], "completed");
    assert_eq!(entry["plan"], "dc_step 60 → 248 V");
    assert_eq!(entry["motor_id"], "seed-table4-dc");
    let ra = entry["key_results"]["params"]["Ra"].as_f64().unwrap();
    assert!((ra / 30.9 - 1.0).abs() < 0.05, "Ra {ra}");

    // The report and the MCAP come back through the API, and the MCAP
    // replays to the recorded result.
    let fetched = dir.path().join("fetched");
    let out = served.ctl(&["fetch", &id, "--out", fetched.to_str().unwrap()]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    let mcap = fetched.join(format!("{id}.mcap"));
    let report: Value = serde_json::from_str(
        &std::fs::read_to_string(fetched.join(format!("{id}.report.json"))).unwrap(),
    )
    .unwrap();
    assert_eq!(report["best"], entry["key_results"]["method"]);
    let replay = common::motorbench(&["replay", mcap.to_str().unwrap(), "--check"]);
    let (_, replay_err) = common::text(&replay);
    assert!(replay.status.success(), "{replay_err}");
    assert!(replay_err.contains("identical"), "{replay_err}");

    // The full staircase (8 levels and a coast-down); a second start is
    // refused with the running test's id.
    let r = start(&c, None).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    let busy = start(&c, None).await;
    assert_eq!(busy.status, 409);
    assert_eq!(busy.json()["error"], "busy");
    assert_eq!(busy.json()["running_test"], id.as_str());
    let rigs = get(&c, "/v1/rigs").await;
    assert_eq!(rigs["rigs"][0]["state"], "running");
    assert_eq!(rigs["rigs"][0]["running_test"], id.as_str());

    // Abort halfway through the plan.
    let s = wait_test(&c, &id, |s| {
        s["segment"]["index"].as_u64().unwrap_or(0) * 2
            >= s["segment"]["total"].as_u64().unwrap_or(99)
    })
    .await;
    assert!(s["eta_s"].as_f64().unwrap() > 0.0, "{s}");
    assert!(s["values"]["current"].is_number(), "{s}");
    let sent = Instant::now();
    let r = c
        .post(&format!("/v1/tests/{id}/abort"), None)
        .await
        .unwrap();
    let round_trip = sent.elapsed();
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    let stop = &r.json()["stop"];
    assert_eq!(stop["kind"], "operator_abort");
    assert_eq!(stop["safe_state_ok"], true);

    let s = wait_test(&c, &id, finished).await;
    assert_eq!(s["outcome"], "aborted");
    let stop = &s["stop"];
    let requested = stop["requested_t_s"].as_f64().unwrap();
    let first_safe = stop["first_safe_sample_t_s"]
        .as_f64()
        .expect("a sample after the safe state");
    let period = 1.0 / 2000.0;

    // What the record says: the abort event, the supervisor's account, and
    // the first sample after the safe state with the armature open.
    let rec = read_mcap(&records.join(format!("{id}.mcap"))).unwrap();
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
    assert!(rec
        .events
        .iter()
        .any(|(_, e)| e.message.starts_with("safety supervisor: operator abort")));
    let mut samples: Vec<(f64, f64)> = rec
        .segments
        .iter()
        .flat_map(|s| s.time.iter().copied().zip(s.current.iter().copied()))
        .collect();
    samples.sort_by(|a, b| a.0.total_cmp(&b.0));
    let at = |t: f64| {
        samples
            .iter()
            .find(|(ts, _)| (ts - t).abs() < period / 10.0)
            .unwrap_or_else(|| panic!("no sample at {t} s"))
            .1
    };
    assert!(
        at(first_safe).abs() < 0.02,
        "current after the safe state: {}",
        at(first_safe)
    );
    let last_driven = samples
        .iter()
        .rev()
        .find(|(_, i)| i.abs() >= 0.02)
        .expect("the motor was driven");
    assert!(
        last_driven.0 <= first_safe,
        "no current after the safe state"
    );
    assert_eq!(record_entry(&c, &id).await["outcome"], "aborted");

    println!(
        "ABORT LATENCY: request received → safe-state command returned {:.3} ms (wall clock, daemon side); \
         abort HTTP round trip {:.3} ms (client side); \
         last sample before the request at {requested:.4} s, first sample read after the safe state at \
         {first_safe:.4} s: {:.0} sample periods of {:.1} ms (test time); \
         last sample with current ≥ 20 mA at {:.4} s",
        stop["safe_after_s"].as_f64().unwrap() * 1e3,
        round_trip.as_secs_f64() * 1e3,
        (first_safe - requested) / period,
        period * 1e3,
        last_driven.0,
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigkill_mid_test_leaves_a_record_that_replays_and_is_marked_interrupted() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let mut served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let r = start(&c, None).await;
    assert_eq!(r.status, 201);
    let id = r.json()["id"].as_str().unwrap().to_string();
    // Well past the first flushes (the recorder flushes at each segment
    // marker and after each second of test time).
    let s = wait_test(&c, &id, |s| s["t_s"].as_f64().unwrap_or(0.0) >= 2.5).await;
    served.child.kill().unwrap(); // SIGKILL
    let t_kill = s["t_s"].as_f64().unwrap();
    served.child.wait().unwrap();

    let mcap = records.join(format!("{id}.mcap"));
    let rec = read_mcap(&mcap).unwrap();
    let recovery = rec.recovery.as_ref().expect("a truncated file");
    assert!(recovery.messages > 10_000, "{recovery:?}");
    let last = rec
        .segments
        .iter()
        .filter_map(|s| s.time.last().copied())
        .fold(0.0, f64::max);
    // At most the flush interval (1 s of test time) and the writer's queue
    // are lost.
    assert!(
        last > 0.5 && last >= t_kill - 2.0,
        "replays up to the last flushed chunk: {last} s of {t_kill} s"
    );
    let replay = common::motorbench(&["replay", mcap.to_str().unwrap()]);
    let (_, err) = common::text(&replay);
    assert!(
        err.contains("damaged") && err.contains("recovered"),
        "{err}"
    );
    println!(
        "SIGKILL at test time {t_kill:.3} s (or a little later): replay recovered {} messages, samples up to {last:.3} s: {}",
        recovery.messages,
        err.lines().next().unwrap_or("")
    );

    // The next start marks it interrupted, with what was recovered.
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let entry = record_entry(&c, &id).await;
    assert_eq!(entry["outcome"], "interrupted", "{entry}");
    assert_eq!(
        entry["recovered"]["messages"].as_u64(),
        Some(recovery.messages),
        "{entry}"
    );
    assert!(served.log().contains("interrupted"), "{}", served.log());
    // And the rig is free for the next test.
    assert_eq!(get(&c, "/v1/rigs").await["rigs"][0]["state"], "idle");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_stops_the_test_safely_finishes_the_mcap_and_exits_0() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let mut served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let r = start(&c, None).await;
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_test(&c, &id, |s| s["t_s"].as_f64().unwrap_or(0.0) >= 1.0).await;
    let kill = Command::new("kill")
        .args(["-TERM", &served.child.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    let status = served.child.wait().unwrap();
    assert_eq!(status.code(), Some(0), "{}", served.log());

    let bytes = std::fs::read(records.join(format!("{id}.mcap"))).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .expect("a whole file")
        .expect("with its summary");
    assert!(summary.stats.unwrap().message_count > 1000);
    let rec = read_mcap(&records.join(format!("{id}.mcap"))).unwrap();
    assert!(rec.recovery.is_none());
    assert!(rec.recorded_result.is_some(), "identified and recorded");
    let abort = rec
        .events
        .iter()
        .find(|(_, e)| e.level == EventLevel::Abort)
        .unwrap();
    assert!(
        abort.1.message.contains("shutting down"),
        "{}",
        abort.1.message
    );
    let index: Value =
        serde_json::from_str(&std::fs::read_to_string(records.join("index.json")).unwrap())
            .unwrap();
    assert_eq!(index["records"][0]["outcome"], "aborted");
    assert!(served.log().contains("stopped"), "{}", served.log());
}

/// Every endpoint, with a method and a path that exists.
const ENDPOINTS: [(&str, &str); 19] = [
    ("GET", "/v1/health"),
    ("GET", "/v1/openapi.json"),
    ("GET", "/metrics"),
    ("GET", "/v1/rigs"),
    ("GET", "/v1/rigs/rig"),
    ("POST", "/v1/rigs/rig/tests"),
    ("POST", "/v1/rigs/rig/estop"),
    ("POST", "/v1/rigs/rig/reset"),
    ("GET", "/v1/tests"),
    ("GET", "/v1/tests/x"),
    ("GET", "/v1/tests/x/events"),
    ("POST", "/v1/tests/x/abort"),
    ("GET", "/v1/records"),
    ("GET", "/v1/records/x"),
    ("GET", "/v1/records/x/report"),
    ("GET", "/v1/records/x/mcap"),
    ("GET", "/v1/records/x/svg"),
    ("GET", "/v1/records/x/residuals"),
    ("GET", "/no/such/path"),
];

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn off_loopback_no_endpoint_answers_without_the_token() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    std::fs::write(
        dir.path().join("rig.toml"),
        motorbench::config::DEFAULT_CONFIG,
    )
    .unwrap();

    // No token file: refused at start.
    let out = Command::new(BIN)
        .args(["serve", "--listen", "0.0.0.0:0", "--config"])
        .arg(dir.path().join("rig.toml"))
        .arg("--records")
        .arg(&records)
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(
        common::text(&out).1.contains("--token-file"),
        "{:?}",
        common::text(&out)
    );

    // With one: bound to every interface, reached here on loopback only.
    let token = "a1b2c3d4e5f60718293a4b5c6d7e8f90";
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, format!("{token}\n")).unwrap();
    let served = start_daemon(
        dir.path(),
        &records,
        &[
            "--listen",
            "0.0.0.0:0",
            "--token-file",
            token_file.to_str().unwrap(),
        ],
    );
    assert!(served.url.starts_with("http://0.0.0.0:"), "{}", served.url);
    for who in [
        None,
        Some("wrong-token-wrong-token-wrong-tok"),
        Some(&token[1..]),
    ] {
        let c = served.client(who);
        for (method, path) in ENDPOINTS {
            let r = c
                .request(method.parse().unwrap(), path, None)
                .await
                .unwrap();
            assert_eq!(r.status, 401, "{method} {path} with {who:?}");
            assert_eq!(r.json()["error"], "unauthorized");
        }
    }
    // The status page's own files (code, no data) load without the token:
    // a browser needs them to ask for it.
    let anon = served.client(None);
    for path in ["/", "/ui/app.js", "/ui/uplot.js"] {
        let r = anon.get(path).await.unwrap();
        assert_eq!(r.status, 200, "{path}");
    }
    // Nothing was started, stopped or latched by those requests.
    let c = served.client(Some(token));
    let rigs = get(&c, "/v1/rigs").await;
    assert_eq!(rigs["rigs"][0]["state"], "idle");
    assert_eq!(get(&c, "/v1/tests").await["tests"], json!([]));
    // The token opens every endpoint (here: 200 or a 404 for the unknown ids).
    for (method, path) in ENDPOINTS {
        if method == "POST" {
            continue;
        }
        let r = c
            .request(method.parse().unwrap(), path, None)
            .await
            .unwrap();
        assert!(
            r.status == 200 || r.status == 404,
            "{method} {path}: {}",
            r.status
        );
    }
    // ctl sends the token from its file.
    let out = served.ctl(&["--token-file", token_file.to_str().unwrap(), "status"]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    let out = served.ctl(&["status"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        common::text(&out).1.contains("401"),
        "{:?}",
        common::text(&out)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn hostile_test_overrides_get_400_naming_the_field_and_the_daemon_stays_up() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let many_levels: Vec<f64> = (0..5000).map(|k| 10.0 + (k % 200) as f64).collect();
    // The first once answered 201 and aborted the daemon a second later
    // allocating 320 GB.
    for (test, field) in [
        (
            json!({"levels_V": [60, 248], "coastdown": false, "settle": {"window_s": 1e7}}),
            "test.settle.window_s",
        ),
        (
            json!({"settle": {"timeout_s": 1e9}}),
            "test.settle.timeout_s",
        ),
        (
            json!({"settle": {"coastdown_timeout_s": 1e300}}),
            "test.settle.coastdown_timeout_s",
        ),
        (json!({"settle": {"hold_s": 4000}}), "test.settle.hold_s"),
        (json!({"levels_V": many_levels}), "test.levels_V"),
    ] {
        let r = start(&c, Some(test.clone())).await;
        let body = String::from_utf8_lossy(&r.body).to_string();
        assert_eq!(r.status, 400, "{test}: {body}");
        assert_eq!(r.json()["error"], "bad_request", "{body}");
        let message = r.json()["message"].as_str().unwrap().to_string();
        assert!(message.contains(&format!("{field}: ")), "{test}: {message}");
    }
    // Still up, the rig idle, and no record was started.
    assert_eq!(get(&c, "/v1/health").await["healthy"], true);
    assert_eq!(get(&c, "/v1/rigs/rig").await["state"], "idle");
    let listed = get(&c, "/v1/records").await;
    assert_eq!(
        listed["records"].as_array().map(Vec::len),
        Some(0),
        "{listed}"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_speed_trip_latches_the_rig_names_the_cause_and_shows_it_safe() {
    // 60 V turns the shaft at about 45 rad/s: a 30 rad/s limit trips on the
    // way up to the first level, seen first by the sequencer's one-period
    // speed estimate.
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let config =
        motorbench::config::DEFAULT_CONFIG.replace("max_speed_rad_s = 230", "max_speed_rad_s = 30");
    assert_ne!(config, motorbench::config::DEFAULT_CONFIG);
    std::fs::write(dir.path().join("rig.toml"), config).unwrap();
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);

    let plan = json!({"levels_V": [60, 100], "coastdown": false});
    let r = start(&c, Some(plan.clone())).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    let s = wait_test(&c, &id, finished).await;
    assert_eq!(s["outcome"], "aborted", "{s}");
    let stop = &s["stop"];
    assert_eq!(stop["kind"], "limit", "{s}");
    assert!(
        stop["message"].as_str().unwrap().contains("speed"),
        "{stop}"
    );
    assert_eq!(stop["safe_state_ok"], true);
    let requested = stop["requested_t_s"].as_f64().unwrap();
    let first_safe = stop["first_safe_sample_t_s"]
        .as_f64()
        .unwrap_or_else(|| panic!("a sample after the safe state: {stop}"));
    assert!(first_safe > requested, "{stop}");

    // The record holds that sample, with the armature open.
    let rec = read_mcap(&records.join(format!("{id}.mcap"))).unwrap();
    let at_safe = rec
        .segments
        .iter()
        .flat_map(|s| s.time.iter().zip(&s.current))
        .find(|(t, _)| (*t - first_safe).abs() < 1e-7)
        .map(|(_, i)| *i)
        .expect("the first safe sample is recorded");
    assert!(
        at_safe.abs() < 0.02,
        "current after the safe state {at_safe}"
    );

    // Latched, as for a voltage trip: refused until reset.
    assert_eq!(get(&c, "/v1/rigs/rig").await["state"], "tripped");
    let refused = start(&c, Some(plan.clone())).await;
    assert_eq!(refused.status, 409);
    assert_eq!(refused.json()["error"], "tripped");
    let out = served.ctl(&["reset"]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    let again = start(&c, Some(plan)).await;
    assert_eq!(
        again.status,
        201,
        "{}",
        String::from_utf8_lossy(&again.body)
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn unix_socket_emergency_stop_latches_until_reset() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let socket = dir.path().join("api.sock");
    let served = start_daemon(dir.path(), &records, &["--unix", socket.to_str().unwrap()]);
    assert_eq!(served.url, format!("unix:{}", socket.display()));
    let c = served.client(None);

    let r = start(&c, None).await;
    assert_eq!(r.status, 201);
    let id = r.json()["id"].as_str().unwrap().to_string();
    wait_test(&c, &id, |s| s["t_s"].as_f64().unwrap_or(0.0) >= 0.5).await;
    let out = served.ctl(&["estop"]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    let s = wait_test(&c, &id, finished).await;
    assert_eq!(s["outcome"], "aborted");
    assert_eq!(s["stop"]["kind"], "emergency_stop");
    assert_eq!(s["stop"]["safe_state_ok"], true);

    // Latched: no new test until an operator resets the rig.
    let rig = get(&c, "/v1/rigs/rig").await;
    assert_eq!(rig["state"], "tripped");
    let refused = start(&c, None).await;
    assert_eq!(refused.status, 409);
    assert_eq!(refused.json()["error"], "tripped");
    let out = served.ctl(&["reset"]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    assert_eq!(get(&c, "/v1/rigs/rig").await["state"], "idle");
    let again = start(&c, Some(json!({"levels_V": [60, 100], "coastdown": false}))).await;
    assert_eq!(
        again.status,
        201,
        "{}",
        String::from_utf8_lossy(&again.body)
    );
    let id = again.json()["id"].as_str().unwrap().to_string();
    // A bad override is refused with the key named.
    let bad = c
        .post(
            "/v1/rigs/rig/tests",
            Some(&json!({"test": {"levels_V": [60, 900]}})),
        )
        .await
        .unwrap();
    assert!(bad.status == 400 || bad.status == 409, "{}", bad.status);
    let out = served.ctl(&["follow", &id]);
    assert!(out.status.success(), "{:?}", common::text(&out));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tells_systemd_it_is_ready_and_pets_the_watchdog() {
    use std::os::unix::net::UnixDatagram;
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    std::fs::write(
        dir.path().join("rig.toml"),
        motorbench::config::DEFAULT_CONFIG,
    )
    .unwrap();
    let notify = dir.path().join("notify.sock");
    let socket = UnixDatagram::bind(&notify).unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(30)))
        .unwrap();
    let child = Command::new(BIN)
        .args(["serve", "--listen", "127.0.0.1:0", "--config"])
        .arg(dir.path().join("rig.toml"))
        .arg("--records")
        .arg(&records)
        .env("NOTIFY_SOCKET", &notify)
        .env("WATCHDOG_USEC", "200000")
        // Claims a journal on stderr; there is no journald here, so the
        // daemon must fall back to plain text.
        .env("JOURNAL_STREAM", "0:0")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut messages = Vec::new();
    let mut buf = [0u8; 512];
    while messages
        .iter()
        .filter(|m: &&String| m.contains("WATCHDOG=1"))
        .count()
        < 3
    {
        let n = socket.recv(&mut buf).expect("a notification within 30 s");
        messages.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    assert!(messages[0].contains("READY=1"), "{messages:?}");
    assert!(
        messages[0].contains("STATUS=listening on http://127.0.0.1:"),
        "{messages:?}"
    );
    Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(0));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("journald unavailable"), "{stderr}");
    assert!(stderr.contains("listening on"), "plain-text logs: {stderr}");
    let mut rest = Vec::new();
    socket.set_nonblocking(true).unwrap();
    while let Ok(n) = socket.recv(&mut buf) {
        rest.push(String::from_utf8_lossy(&buf[..n]).into_owned());
    }
    assert!(rest.iter().any(|m| m.contains("STOPPING=1")), "{rest:?}");
}

/// A short test (one step, no coast-down): a second or so at the wall clock.
fn one_step() -> Value {
    json!({"levels_V": [60, 248], "coastdown": false})
}

/// Send `signal` to the daemon at once (no `kill` process in between).
fn signal(served: &Served, signal: rustix::process::Signal) {
    let pid = rustix::process::Pid::from_raw(served.child.id() as i32).unwrap();
    rustix::process::kill_process(pid, signal).unwrap();
}

/// The daemon on the default configuration with a fake systemd
/// notification socket and a watchdog of `interval`.
fn start_with_watchdog(dir: &Path, interval: Duration) -> (Served, common::daemon::NotifySocket) {
    std::fs::write(dir.join("rig.toml"), motorbench::config::DEFAULT_CONFIG).unwrap();
    let notify = common::daemon::NotifySocket::bind(dir);
    let usec = interval.as_micros().to_string();
    let served = Served::start_with_env(
        &dir.join("rig.toml"),
        &dir.join("records"),
        dir,
        &["--listen", "127.0.0.1:0"],
        &[
            ("NOTIFY_SOCKET", notify.path.as_os_str()),
            ("WATCHDOG_USEC", usec.as_ref()),
        ],
    );
    (served, notify)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_watchdog_is_petted_while_tests_are_identified() {
    let dir = tempfile::tempdir().unwrap();
    // systemd would kill the daemon after 1 s without a `WATCHDOG=1`.
    let interval = Duration::from_secs(1);
    let (served, notify) = start_with_watchdog(dir.path(), interval);
    let c = served.client(None);
    // The full default plan: its analysis (nine segments, the diagnosis
    // included) lasts well over the interval in this build, so a daemon
    // that stopped petting while analysing shows a gap over it.
    let r = start(&c, None).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    // Identification and diagnosis run once the plan has ended and its
    // supervisor's task is gone: the pets must go on meanwhile.
    wait_test(&c, &id, |s| s["state"] != "running").await;
    let pets = notify.pets();
    let t0 = Instant::now();
    loop {
        let s = get(&c, &format!("/v1/tests/{id}")).await;
        if notify.pets() >= pets + 3 || finished(&s) {
            break;
        }
        assert!(t0.elapsed() < common::daemon::PATIENCE, "{s}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let gap = notify.largest_gap();
    assert!(
        gap < interval,
        "{gap:?} without a WATCHDOG=1 (systemd kills at {interval:?}); {}",
        served.log()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
#[ignore = "a measurement: MOTORBENCH_WATCHDOG_TESTS full-plan tests (default 50), minutes"]
async fn measure_watchdog_gaps_over_many_full_plan_tests() {
    let tests: usize = std::env::var("MOTORBENCH_WATCHDOG_TESTS")
        .ok()
        .and_then(|n| n.parse().ok())
        .unwrap_or(50);
    let dir = tempfile::tempdir().unwrap();
    // The shipped unit's WatchdogSec=5s.
    let (served, notify) = start_with_watchdog(dir.path(), Duration::from_secs(5));
    let c = served.client(None);
    let mut worst = Vec::new();
    for k in 0..tests {
        let before = notify.gaps().len();
        let r = start(&c, None).await;
        assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
        let id = r.json()["id"].as_str().unwrap().to_string();
        let s = wait_test(&c, &id, finished).await;
        assert_eq!(s["outcome"], "completed", "{s}");
        let gaps = notify.gaps();
        let test_worst = gaps[before..].iter().max().copied().unwrap_or_default();
        println!("test {k}: largest gap {:.3} s", test_worst.as_secs_f64());
        worst.push(test_worst);
    }
    let gaps = notify.gaps();
    let over = |limit: f64| gaps.iter().filter(|g| g.as_secs_f64() > limit).count();
    println!(
        "WATCHDOG GAPS over {tests} full-plan tests (petting every 2.5 s, WatchdogSec=5s): \
         {} pets, largest gap {:.3} s, gaps over 2.6 s: {}, over 5 s: {}",
        gaps.len() + 1,
        notify.largest_gap().as_secs_f64(),
        over(2.6),
        over(5.0),
    );
    assert_eq!(over(5.0), 0, "systemd would have killed the daemon");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_record_killed_during_its_analysis_keeps_what_it_holds_and_a_cut_index_is_rebuilt() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let mut served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    // Killed while identifying: the plan's data is all on disk.
    let r = start(&c, Some(one_step())).await;
    let cut = r.json()["id"].as_str().unwrap().to_string();
    wait_test(&c, &cut, |s| s["state"] != "running").await;
    served.child.kill().unwrap();
    served.child.wait().unwrap();

    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let entry = record_entry(&c, &cut).await;
    if entry["outcome"] == "completed" {
        // The record held its result (the identification is written
        // before the diagnosis, or the analysis had finished before the
        // kill landed): its key results are in the index.
        let rec = read_mcap(&records.join(format!("{cut}.mcap"))).unwrap();
        let best = rec
            .recorded_result
            .as_ref()
            .and_then(|r| r["best"].as_str());
        assert!(best.is_some(), "{entry}");
        assert_eq!(entry["key_results"]["method"].as_str(), best, "{entry}");
    } else {
        assert_eq!(entry["outcome"], "unanalysed", "{entry}");
        let reason = entry["reason"].as_str().unwrap();
        assert!(reason.contains("motorbench replay"), "{reason}");
        let rec = read_mcap(&records.join(format!("{cut}.mcap"))).unwrap();
        assert!(rec.recorded_result.is_none());
        assert_eq!(rec.segments.len(), 2, "every segment was recorded");
    }
    // A whole record: a test aborted at once (little to analyse).
    let r = start(&c, Some(one_step())).await;
    let whole = r.json()["id"].as_str().unwrap().to_string();
    let abort = c
        .post(&format!("/v1/tests/{whole}/abort"), None)
        .await
        .unwrap();
    assert_eq!(
        abort.status,
        200,
        "{}",
        String::from_utf8_lossy(&abort.body)
    );
    let s = wait_test(&c, &whole, finished).await;
    assert_eq!(s["outcome"], "aborted", "{s}");
    drop(served);

    // A cut index: rebuilt from the records' own metadata and results.
    let index = records.join("index.json");
    let text = std::fs::read(&index).unwrap();
    std::fs::write(&index, &text[..text.len() / 2]).unwrap();
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    assert!(records.join("index.json.corrupt").exists());
    let entry = record_entry(&c, &whole).await;
    assert_eq!(entry["outcome"], "aborted", "{entry}");
    assert!(
        entry["reason"].as_str().unwrap().contains("operator abort"),
        "{entry}"
    );
    // The rig whose motor it recorded: retention applies to it again.
    assert_eq!(entry["rig"], "rig", "{entry}");
    assert_eq!(entry["motor_id"], "seed-table4-dc", "{entry}");
    assert_eq!(entry["kind"], "dc_step", "{entry}");
    assert!(entry["bytes"].as_u64().unwrap() > 0, "{entry}");
    let rec = read_mcap(&records.join(format!("{whole}.mcap"))).unwrap();
    let best = rec
        .recorded_result
        .as_ref()
        .and_then(|r| r["best"].as_str());
    assert_eq!(entry["key_results"]["method"].as_str(), best, "{entry}");
    let entry = record_entry(&c, &cut).await;
    assert_eq!(entry["rig"], "rig", "{entry}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sigterm_right_after_listening_is_a_clean_stop() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    for _ in 0..10 {
        let mut served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
        signal(&served, rustix::process::Signal::TERM);
        let status = served.child.wait().unwrap();
        assert_eq!(status.code(), Some(0), "{status:?}: {}", served.log());
        assert!(served.log().contains("stopped"), "{}", served.log());
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_second_daemon_does_not_take_over_a_live_unix_socket() {
    use std::io::BufRead;
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let socket = dir.path().join("api.sock");
    let mut served = start_daemon(dir.path(), &records, &["--unix", socket.to_str().unwrap()]);
    let mode = std::fs::metadata(&socket).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o660, "{mode:o}");

    let mut second = Command::new(BIN)
        .args(["serve", "--unix", socket.to_str().unwrap(), "--config"])
        .arg(dir.path().join("rig.toml"))
        .arg("--records")
        .arg(dir.path().join("records2"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(second.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    if !line.is_empty() {
        let _ = second.kill();
    }
    let out = second.wait_with_output().unwrap();
    assert_eq!(line, "", "the second daemon took the socket over");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("another daemon is listening"), "{err}");
    // The first still answers on it.
    assert_eq!(
        get(&served.client(None), "/v1/rigs").await["rigs"][0]["state"],
        "idle"
    );

    // A socket nobody answers on (its daemon was killed) is replaced.
    served.child.kill().unwrap();
    served.child.wait().unwrap();
    assert!(socket.exists());
    let served = start_daemon(dir.path(), &records, &["--unix", socket.to_str().unwrap()]);
    assert_eq!(
        get(&served.client(None), "/v1/rigs").await["rigs"][0]["state"],
        "idle"
    );
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

/// Read from `stream` until the peer closes it; what was read.
async fn read_to_close(stream: &mut tokio::net::TcpStream) -> Vec<u8> {
    use tokio::io::AsyncReadExt;
    let mut got = Vec::new();
    tokio::time::timeout(common::daemon::PATIENCE, stream.read_to_end(&mut got))
        .await
        .expect("the daemon closed the connection")
        .unwrap();
    got
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn partial_and_idle_connections_are_closed_after_the_header_timeout() {
    use tokio::io::AsyncWriteExt;
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let served = start_daemon(
        dir.path(),
        &records,
        &["--listen", "127.0.0.1:0", "--header-timeout", "300ms"],
    );
    let addr = served.url.strip_prefix("http://").unwrap().to_string();
    // Headers never finished.
    let mut partial = tokio::net::TcpStream::connect(&addr).await.unwrap();
    partial
        .write_all(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n")
        .await
        .unwrap();
    // Nothing sent at all.
    let mut silent = tokio::net::TcpStream::connect(&addr).await.unwrap();
    // One whole request, then idle on the kept-alive connection.
    let mut idle = tokio::net::TcpStream::connect(&addr).await.unwrap();
    idle.write_all(b"GET /v1/health HTTP/1.1\r\nHost: x\r\n\r\n")
        .await
        .unwrap();
    // A body that never comes.
    let mut body = tokio::net::TcpStream::connect(&addr).await.unwrap();
    body.write_all(b"POST /v1/rigs/rig/tests HTTP/1.1\r\nHost: x\r\ncontent-length: 100\r\n\r\n{")
        .await
        .unwrap();
    assert!(read_to_close(&mut partial).await.is_empty());
    assert!(read_to_close(&mut silent).await.is_empty());
    let answered = String::from_utf8_lossy(&read_to_close(&mut idle).await).into_owned();
    assert!(answered.starts_with("HTTP/1.1 200"), "{answered}");
    let timed_out = String::from_utf8_lossy(&read_to_close(&mut body).await).into_owned();
    assert!(timed_out.starts_with("HTTP/1.1 408"), "{timed_out}");
    // Nothing was started by the cut request.
    assert_eq!(
        get(&served.client(None), "/v1/tests").await["tests"],
        json!([])
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn at_the_connection_limit_emergency_stop_still_works() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let served = start_daemon(
        dir.path(),
        &records,
        &[
            "--listen",
            "127.0.0.1:0",
            "--max-connections",
            "3",
            "--header-timeout",
            "120s",
        ],
    );
    let addr = served.url.strip_prefix("http://").unwrap().to_string();
    let c = served.client(None);
    // Three idle connections fill the table.
    let mut idle = Vec::new();
    for _ in 0..3 {
        idle.push(tokio::net::TcpStream::connect(&addr).await.unwrap());
    }
    // A reserved connection serves the stop endpoints and nothing else.
    let r = c.get("/v1/rigs").await.unwrap();
    assert_eq!(r.status, 503, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["error"], "too_many_connections");
    let r = c.post("/v1/rigs/rig/estop", None).await.unwrap();
    assert_eq!(r.status, 200, "{}", String::from_utf8_lossy(&r.body));
    assert_eq!(r.json()["state"], "tripped");

    // The signal needs no connection at all.
    signal(&served, rustix::process::Signal::USR1);
    let t0 = Instant::now();
    while !served.log().contains("SIGUSR1") {
        assert!(t0.elapsed() < common::daemon::PATIENCE, "{}", served.log());
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    // With the reserve taken too, a connection is answered 503 and closed.
    for _ in 0..4 {
        idle.push(tokio::net::TcpStream::connect(&addr).await.unwrap());
    }
    let mut refused = tokio::net::TcpStream::connect(&addr).await.unwrap();
    let got = String::from_utf8_lossy(&read_to_close(&mut refused).await).into_owned();
    assert!(
        got.starts_with("HTTP/1.1 503") && got.contains("too_many_connections"),
        "{got}"
    );

    // Once they close, the whole API is back, and the rig is latched.
    drop(idle);
    let t0 = Instant::now();
    // Until the daemon has seen them close, a new connection may still be
    // over the limit: answered 503, or closed before the client's request
    // went out (a connect error to the client). Both are retried.
    let rig = loop {
        match c.get("/v1/rigs/rig").await {
            Ok(r) if r.status == 200 => break r.json(),
            Ok(r) => assert!(t0.elapsed() < common::daemon::PATIENCE, "{}", r.status),
            Err(e) => assert!(t0.elapsed() < common::daemon::PATIENCE, "{e:?}"),
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    };
    assert_eq!(rig["state"], "tripped", "{rig}");
    assert!(served.log().contains("too many") || served.log().contains("the limit"));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_latch_survives_a_killed_daemon_until_reset() {
    let dir = tempfile::tempdir().unwrap();
    let records = dir.path().join("records");
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let out = served.ctl(&["estop"]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    assert_eq!(get(&c, "/v1/rigs/rig").await["state"], "tripped");
    // SIGKILL (Served's drop), then a new daemon on the same records.
    drop(served);
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    let rig = get(&c, "/v1/rigs/rig").await;
    assert_eq!(rig["state"], "tripped", "{rig}");
    assert_eq!(rig["trip"]["kind"], "emergency_stop", "{rig}");
    let refused = start(&c, None).await;
    assert_eq!(refused.status, 409);
    let out = served.ctl(&["reset"]);
    assert!(out.status.success(), "{:?}", common::text(&out));
    // The reset is kept too.
    drop(served);
    let served = start_daemon(dir.path(), &records, &["--listen", "127.0.0.1:0"]);
    let c = served.client(None);
    assert_eq!(get(&c, "/v1/rigs/rig").await["state"], "idle");
}
