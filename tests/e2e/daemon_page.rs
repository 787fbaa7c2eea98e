//! End to end: the daemon's status page in a real browser. Debian's
//! Chromium runs headless, driven through its DevTools protocol by
//! `tests/python/page_check.py`, against a daemon behind a token running
//! the full DC staircase on the simulated rig (paced at the wall clock).
//!
//! The page must ask for the token, then show the rig running with the
//! test's segment, time, ETA and a plot fed from the event stream; its
//! Abort button must abort the test (the daemon's record says who
//! stopped it); the record's report and plot open from the records list;
//! its emergency stop latches the rig and its reset clears it. The page
//! loads nothing but the daemon's own files. Screenshots are kept in
//! `target/daemon-page/` for a person to look at. Without Chromium the
//! test fails (tests/run.sh installs it).
//!
//! A second test runs an induction-machine slip sweep (the simulated rig
//! of `config/sim-im.toml`): the page must plot the sweep's operating
//! points, line current and input power against slip, as they arrive,
//! the same points the API's status holds.
//!
//! A third cuts every event feed in the browser (a dropped connection, a
//! proxy that closes long answers): the page must still show the test
//! from its status and, once aborted from the page, how it ended, though
//! the rig is idle by then.

use crate::common;

use std::path::Path;

use motorbench::serve::client::Client;
use serde_json::Value;

use common::daemon::{
    finished, get, python_script, shipped, start_config_with_token, start_with_token, wait_test,
    Served, WEB_TOKEN,
};

/// Where the page checks keep their screenshots.
fn shots_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("target/daemon-page")
}

/// Start a test on the daemon's rig `rig` with `body`; its id.
async fn start(c: &Client, body: &Value) -> String {
    let r = c.post("/v1/rigs/rig/tests", Some(body)).await.unwrap();
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    r.json()["id"].as_str().unwrap().to_string()
}

/// Start the full DC staircase, each level held 6 s: long enough to load
/// the page, watch and abort however slow the browser starts; its id.
async fn start_slow_staircase(c: &Client) -> String {
    let slow =
        serde_json::json!({"test": {"settle": {"min_hold_s": 6, "hold_s": 2, "timeout_s": 20}}});
    start(c, &slow).await
}

/// Run `tests/python/page_check.py` (`mode` first when given) against
/// the daemon's page following test `id` on rig `rig`; what it saw.
fn page_check(served: &Served, mode: Option<&str>, id: &str) -> Value {
    let shots = shots_dir();
    let url = format!("{}/", served.url);
    let mut args: Vec<&std::ffi::OsStr> = mode.into_iter().map(|m| m.as_ref()).collect();
    args.extend([
        url.as_ref(),
        WEB_TOKEN.as_ref(),
        "rig".as_ref(),
        id.as_ref(),
        shots.as_os_str(),
    ]);
    let out = python_script("page_check.py", &args);
    let (stdout, stderr) = common::text(&out);
    assert!(
        out.status.success(),
        "the page check failed (screenshots in {}):\n{stderr}\n{}",
        shots.display(),
        served.log()
    );
    let seen: Value = serde_json::from_str(&stdout).unwrap();
    println!("{}", serde_json::to_string_pretty(&seen).unwrap());
    seen
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_status_page_shows_the_test_and_aborts_it_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let served = start_with_token(dir.path(), &dir.path().join("records"));
    let c = served.client(Some(WEB_TOKEN));
    let id = start_slow_staircase(&c).await;
    let seen = page_check(&served, None, &id);
    let shots = shots_dir();

    assert!(seen["token_form"].as_str().unwrap().contains("token"));
    let running = &seen["running"];
    assert_eq!(running["badge"], "running");
    let shown = [
        ("segment", "segment "),
        ("segment", " V → "),
        ("eta", "ETA "),
        ("values", " A · ω "),
    ];
    for (field, text) in shown {
        let value = running[field].as_str().unwrap();
        assert!(value.contains(text), "{field}: {value:?} lacks {text:?}");
    }
    assert_eq!(running["canvas"], true, "the plot is drawn");
    assert!(running["points"].as_u64().unwrap() >= 20, "{running}");

    // The abort came from the page: the daemon says so.
    let aborted = &seen["aborted"];
    assert_eq!(aborted["badge"], "idle");
    assert!(
        aborted["message"]
            .as_str()
            .unwrap()
            .starts_with("Aborted: operator abort"),
        "{aborted}"
    );
    let s = wait_test(&c, &id, finished).await;
    assert_eq!(s["outcome"], "aborted");
    assert_eq!(s["stop"]["kind"], "operator_abort");

    let record = &seen["record_view"];
    assert!(
        record["text"].as_str().unwrap().contains("best method"),
        "{record}"
    );
    assert!(record["plot_width"].as_u64().unwrap() > 100, "{record}");

    assert_eq!(seen["latched"]["badge"], "latched");
    assert!(
        seen["latched"]["trip"]
            .as_str()
            .unwrap()
            .contains("emergency stop"),
        "{}",
        seen["latched"]
    );
    assert_eq!(seen["reset"]["badge"], "idle");
    let rig = get(&c, "/v1/rigs/rig").await;
    assert_eq!(rig["state"], "idle", "reset from the page");

    // Only the daemon's own files and API were requested.
    for u in seen["requests"].as_array().unwrap() {
        let u = u.as_str().unwrap();
        assert!(
            u.starts_with(&served.url) || u.starts_with("blob:") || u.starts_with("data:"),
            "the page requested {u}"
        );
    }
    assert_eq!(
        seen["console_errors"],
        Value::Array(vec![]),
        "no script errors"
    );
    for shot in [
        "01-token",
        "02-running",
        "03-aborted",
        "04-record",
        "05-latched",
    ] {
        assert!(shots.join(format!("{shot}.png")).exists(), "{shot}.png");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_status_page_shows_how_a_test_ended_when_its_event_feed_is_cut() {
    let dir = tempfile::tempdir().unwrap();
    let served = start_with_token(dir.path(), &dir.path().join("records"));
    let c = served.client(Some(WEB_TOKEN));
    let id = start_slow_staircase(&c).await;
    let seen = page_check(&served, Some("--cut-feed"), &id);

    assert!(seen["feeds_cut"].as_u64().unwrap() >= 1, "{seen}");
    let running = &seen["running"];
    assert_eq!(running["badge"], "running", "{running}");
    assert!(
        running["segment"].as_str().unwrap().starts_with("segment "),
        "{running}"
    );
    let aborted = &seen["aborted"];
    assert_eq!(aborted["badge"], "idle", "{aborted}");
    assert!(
        aborted["eta"].as_str().unwrap().starts_with("aborted"),
        "{aborted}"
    );
    let s = wait_test(&c, &id, finished).await;
    assert_eq!(s["outcome"], "aborted");
    assert_eq!(s["stop"]["kind"], "operator_abort");
    assert_eq!(seen["console_errors"], Value::Array(vec![]), "{seen}");
    assert!(shots_dir().join("21-feed-cut.png").exists());
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_status_page_plots_a_sweeps_operating_points_in_chromium() {
    let dir = tempfile::tempdir().unwrap();
    let config = std::fs::read_to_string(shipped("sim-im.toml")).unwrap();
    let served = start_config_with_token(&config, dir.path(), &dir.path().join("records"));
    let c = served.client(Some(WEB_TOKEN));
    // One voltage, short cool-downs: points come every second or so.
    let short = serde_json::json!({"test": {"voltages_V": [400], "points": 16, "cooldown_s": 1}});
    let id = start(&c, &short).await;
    let seen = page_check(&served, Some("--sweep"), &id);
    let shots = shots_dir();

    let sweep = &seen["sweep"];
    assert_eq!(sweep["canvas"], true, "the sweep plot is drawn: {sweep}");
    assert_eq!(sweep["visible"], true, "{sweep}");
    assert_eq!(sweep["title"], "sweep operating points", "{sweep}");
    // The series (the axes' labels are drawn on the canvas: see the
    // screenshot).
    assert_eq!(
        sweep["legend"],
        serde_json::json!(["slip", "line current, A", "input power, W"]),
        "{sweep}"
    );
    let first = seen["sweep_first"]["points"].as_u64().unwrap();
    let later = sweep["points"].as_u64().unwrap();
    assert!(
        first >= 3 && later >= first + 2,
        "points arrive: {first} then {later}"
    );
    assert!(sweep["time_points"].as_u64().unwrap() > 0, "{sweep}");

    // The page plotted what the API says the sweep recorded.
    let s = wait_test(&c, &id, finished).await;
    assert_eq!(s["outcome"], "aborted", "aborted from the page: {s}");
    let points = s["operating_points"].as_array().unwrap();
    let shown = seen["aborted"]["sweep"]["points"].as_u64().unwrap();
    assert_eq!(points.len() as u64, shown, "{s}");
    for p in points {
        let slip = p["slip"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&slip), "{p}");
        assert!(p["line_current"].as_f64().unwrap() > 0.0, "{p}");
        assert!(p["input_power"].as_f64().unwrap() > 0.0, "{p}");
    }
    // The record holds the same points.
    let mcap = dir.path().join("records").join(format!("{id}.mcap"));
    let rec = motorbench::record::read_mcap(&mcap).unwrap();
    assert_eq!(rec.operating_points.len(), points.len());
    for (r, p) in rec.operating_points.iter().zip(points) {
        assert_eq!(r.slip, p["slip"].as_f64().unwrap());
        assert_eq!(r.line_current, p["line_current"].as_f64().unwrap());
    }

    for u in seen["requests"].as_array().unwrap() {
        let u = u.as_str().unwrap();
        assert!(
            u.starts_with(&served.url) || u.starts_with("blob:") || u.starts_with("data:"),
            "the page requested {u}"
        );
    }
    assert_eq!(seen["console_errors"], Value::Array(vec![]), "{seen}");
    for shot in ["11-sweep", "12-sweep-aborted"] {
        assert!(shots.join(format!("{shot}.png")).exists(), "{shot}.png");
    }
}
