//! End to end: `motorbench serve` against its own OpenAPI document and
//! its metrics, behind a token on loopback.
//!
//! Every operation the document lists (`/v1/openapi.json`) is called on a
//! running daemon, with the answers it documents (successes, 404s, 409s,
//! a 400, a 401); `tests/python/check_openapi.py` checks each answer's
//! status, content type and body against the document (JSON Schema
//! 2020-12), each server-sent event against `TestStatus`, and that no
//! documented operation was left out. Then `/metrics` is parsed with the
//! Prometheus client library's OpenMetrics parser and its counts compared
//! with what the test did.

use crate::common;

use std::collections::BTreeSet;

use motorbench::serve::client::{Client, Reply};
use serde_json::{json, Value};

use common::daemon::{finished, python_script, start_with_token, wait_test, WEB_TOKEN};

/// The exchanges made, for the document check.
#[derive(Default)]
struct Exchanges(Vec<Value>);

impl Exchanges {
    /// `method path` (of the path template `route`) with an optional JSON
    /// body; the answer, noted.
    async fn call(
        &mut self,
        c: &Client,
        method: &str,
        route: &str,
        path: &str,
        body: Option<Value>,
    ) -> Reply {
        let r = c
            .request(method.parse().unwrap(), path, body.as_ref())
            .await
            .unwrap();
        let text = match r.content_type.as_deref() {
            // The file itself is checked below, not against a schema.
            Some(t) if t.starts_with("application/vnd.mcap") => String::new(),
            _ => String::from_utf8_lossy(&r.body).into_owned(),
        };
        self.0.push(json!({
            "method": method, "route": route, "path": path, "status": r.status,
            "content_type": r.content_type, "body": text,
        }));
        r
    }

    async fn expect(
        &mut self,
        c: &Client,
        method: &str,
        route: &str,
        path: &str,
        status: u16,
    ) -> Reply {
        let r = self.call(c, method, route, path, None).await;
        assert_eq!(
            r.status,
            status,
            "{method} {path}: {}",
            String::from_utf8_lossy(&r.body)
        );
        r
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_documented_route_answers_as_documented_and_metrics_count_it() {
    let dir = tempfile::tempdir().unwrap();
    let served = start_with_token(dir.path(), &dir.path().join("records"));
    let c = served.client(Some(WEB_TOKEN));
    let anon = served.client(None);
    let mut ex = Exchanges::default();

    let doc = ex
        .expect(&c, "GET", "/v1/openapi.json", "/v1/openapi.json", 200)
        .await
        .json();
    assert!(
        doc["openapi"].as_str().unwrap().starts_with("3."),
        "{}",
        doc["openapi"]
    );
    let r = ex.expect(&anon, "GET", "/v1/rigs", "/v1/rigs", 401).await;
    assert_eq!(r.json()["error"], "unauthorized");

    let health = ex.expect(&c, "GET", "/v1/health", "/v1/health", 200).await;
    assert_eq!(health.json()["healthy"], true);
    ex.expect(&c, "GET", "/v1/rigs", "/v1/rigs", 200).await;
    ex.expect(&c, "GET", "/v1/rigs/{rig}", "/v1/rigs/rig", 200)
        .await;
    ex.expect(&c, "GET", "/v1/rigs/{rig}", "/v1/rigs/nope", 404)
        .await;

    // A short test, followed to its end.
    let short = json!({"test": {"levels_V": [60, 248], "coastdown": false}});
    let r = ex
        .call(
            &c,
            "POST",
            "/v1/rigs/{rig}/tests",
            "/v1/rigs/rig/tests",
            Some(short.clone()),
        )
        .await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    let r = ex
        .call(
            &c,
            "POST",
            "/v1/rigs/{rig}/tests",
            "/v1/rigs/rig/tests",
            Some(short),
        )
        .await;
    assert_eq!(r.status, 409);
    assert_eq!(r.json()["running_test"], id.as_str());
    ex.expect(
        &c,
        "POST",
        "/v1/rigs/{rig}/tests",
        "/v1/rigs/nope/tests",
        404,
    )
    .await;
    ex.expect(&c, "GET", "/v1/tests", "/v1/tests", 200).await;
    ex.expect(&c, "GET", "/v1/tests/{id}", &format!("/v1/tests/{id}"), 200)
        .await;
    ex.expect(&c, "GET", "/v1/tests/{id}", "/v1/tests/nope", 404)
        .await;
    ex.expect(
        &c,
        "GET",
        "/v1/tests/{id}/events",
        "/v1/tests/nope/events",
        404,
    )
    .await;
    let events = ex
        .expect(
            &c,
            "GET",
            "/v1/tests/{id}/events",
            &format!("/v1/tests/{id}/events"),
            200,
        )
        .await;
    assert_eq!(events.content_type.as_deref(), Some("text/event-stream"));
    assert!(String::from_utf8_lossy(&events.body).contains("event: done"));
    wait_test(&c, &id, finished).await;

    // The record and its files, each with its own media type.
    ex.expect(&c, "GET", "/v1/records", "/v1/records", 200)
        .await;
    let entry = ex
        .expect(
            &c,
            "GET",
            "/v1/records/{name}",
            &format!("/v1/records/{id}"),
            200,
        )
        .await
        .json();
    assert_eq!(entry["outcome"], "completed");
    ex.expect(
        &c,
        "GET",
        "/v1/records/{name}/report",
        &format!("/v1/records/{id}/report"),
        200,
    )
    .await;
    assert_eq!(
        entry["svg"],
        format!("{id}.svg"),
        "the index lists the plot"
    );
    let svg = ex
        .expect(
            &c,
            "GET",
            "/v1/records/{name}/svg",
            &format!("/v1/records/{id}/svg"),
            200,
        )
        .await;
    assert_eq!(svg.content_type.as_deref(), Some("image/svg+xml"));
    assert!(
        String::from_utf8_lossy(&svg.body).contains("<svg"),
        "an SVG"
    );
    let mcap = ex
        .expect(
            &c,
            "GET",
            "/v1/records/{name}/mcap",
            &format!("/v1/records/{id}/mcap"),
            200,
        )
        .await;
    assert_eq!(mcap.content_type.as_deref(), Some("application/vnd.mcap"));
    assert!(mcap.body.starts_with(b"\x89MCAP"), "an MCAP file");
    for route in [
        "/v1/records/{name}",
        "/v1/records/{name}/report",
        "/v1/records/{name}/svg",
        "/v1/records/{name}/mcap",
    ] {
        ex.expect(&c, "GET", route, &route.replace("{name}", "nope"), 404)
            .await;
    }

    // Aborts: of a finished test, of none, of a running one.
    ex.expect(
        &c,
        "POST",
        "/v1/tests/{id}/abort",
        &format!("/v1/tests/{id}/abort"),
        409,
    )
    .await;
    ex.expect(
        &c,
        "POST",
        "/v1/tests/{id}/abort",
        "/v1/tests/nope/abort",
        404,
    )
    .await;
    let bad = json!({"test": {"levels_V": [900]}});
    let r = ex
        .call(
            &c,
            "POST",
            "/v1/rigs/{rig}/tests",
            "/v1/rigs/rig/tests",
            Some(bad),
        )
        .await;
    assert_eq!(r.status, 400, "{}", String::from_utf8_lossy(&r.body));
    let r = ex
        .expect(
            &c,
            "POST",
            "/v1/rigs/{rig}/tests",
            "/v1/rigs/rig/tests",
            201,
        )
        .await;
    let id2 = r.json()["id"].as_str().unwrap().to_string();
    wait_test(&c, &id2, |s| {
        s["segment"]["index"].as_u64().unwrap_or(0) >= 1
    })
    .await;
    let r = ex
        .expect(
            &c,
            "POST",
            "/v1/tests/{id}/abort",
            &format!("/v1/tests/{id2}/abort"),
            200,
        )
        .await;
    assert_eq!(r.json()["stop"]["kind"], "operator_abort");
    wait_test(&c, &id2, finished).await;

    // Emergency stop, refused start, reset.
    let r = ex
        .expect(
            &c,
            "POST",
            "/v1/rigs/{rig}/estop",
            "/v1/rigs/rig/estop",
            200,
        )
        .await;
    assert_eq!(r.json()["state"], "tripped");
    let r = ex
        .expect(
            &c,
            "POST",
            "/v1/rigs/{rig}/tests",
            "/v1/rigs/rig/tests",
            409,
        )
        .await;
    assert_eq!(r.json()["error"], "tripped");
    ex.expect(
        &c,
        "POST",
        "/v1/rigs/{rig}/reset",
        "/v1/rigs/rig/reset",
        200,
    )
    .await;
    ex.expect(
        &c,
        "POST",
        "/v1/rigs/{rig}/estop",
        "/v1/rigs/nope/estop",
        404,
    )
    .await;
    ex.expect(
        &c,
        "POST",
        "/v1/rigs/{rig}/reset",
        "/v1/rigs/nope/reset",
        404,
    )
    .await;
    let metrics = ex.expect(&c, "GET", "/metrics", "/metrics", 200).await;

    // Every answer against the document, every operation exercised.
    let documented: BTreeSet<String> = doc["paths"]
        .as_object()
        .unwrap()
        .iter()
        .flat_map(|(p, item)| {
            item.as_object()
                .unwrap()
                .keys()
                .map(move |m| format!("{} {p}", m.to_uppercase()))
        })
        .collect();
    let called: BTreeSet<String> =
        ex.0.iter()
            .map(|e| {
                format!(
                    "{} {}",
                    e["method"].as_str().unwrap(),
                    e["route"].as_str().unwrap()
                )
            })
            .collect();
    assert_eq!(
        documented, called,
        "every documented operation, and only those"
    );
    let doc_file = dir.path().join("openapi.json");
    let ex_file = dir.path().join("exchanges.json");
    std::fs::write(&doc_file, doc.to_string()).unwrap();
    std::fs::write(&ex_file, Value::Array(ex.0).to_string()).unwrap();
    let out = python_script(
        "check_openapi.py",
        &[doc_file.as_os_str(), ex_file.as_os_str()],
    );
    let (stdout, stderr) = common::text(&out);
    println!("{stdout}");
    assert!(out.status.success(), "{stdout}\n{stderr}");

    // The metrics, through a Prometheus parser.
    let metrics_file = dir.path().join("metrics.txt");
    std::fs::write(&metrics_file, &metrics.body).unwrap();
    let out = python_script("parse_metrics.py", &[metrics_file.as_os_str()]);
    let (stdout, stderr) = common::text(&out);
    assert!(
        out.status.success(),
        "{stderr}\n{}",
        String::from_utf8_lossy(&metrics.body)
    );
    let samples: Vec<Value> = serde_json::from_str(&stdout).unwrap();
    let value = |name: &str, labels: &[(&str, &str)]| -> f64 {
        samples
            .iter()
            .filter(|s| s["name"] == name && labels.iter().all(|(k, v)| s["labels"][*k] == *v))
            .map(|s| s["value"].as_f64().unwrap())
            .sum()
    };
    let rig = ("rig", "rig");
    assert_eq!(value("motorbench_tests_started_total", &[rig]), 2.0);
    assert_eq!(
        value(
            "motorbench_tests_finished_total",
            &[rig, ("outcome", "completed")]
        ),
        1.0
    );
    assert_eq!(
        value(
            "motorbench_tests_finished_total",
            &[rig, ("outcome", "aborted")]
        ),
        1.0
    );
    assert_eq!(
        value(
            "motorbench_tests_stopped_total",
            &[rig, ("cause", "operator_abort")]
        ),
        1.0
    );
    assert_eq!(
        value(
            "motorbench_emergency_stops_total",
            &[rig, ("source", "API")]
        ),
        1.0
    );
    assert_eq!(
        value("motorbench_rig_state", &[rig, ("state", "idle")]),
        1.0
    );
    assert_eq!(
        value("motorbench_rig_state", &[rig, ("state", "tripped")]),
        0.0
    );
    assert_eq!(value("motorbench_records_written_total", &[rig]), 2.0);
    assert!(value("motorbench_record_written_bytes_total", &[rig]) > 1000.0);
    assert!(value("motorbench_recorded_messages_total", &[rig]) > 100.0);
    assert!(value("motorbench_last_test_duration_seconds", &[rig]) > 0.0);
    let winding = value("motorbench_winding_temperature_celsius", &[rig]);
    assert!((20.0..200.0).contains(&winding), "winding {winding}");
    let posts = [("method", "POST"), ("route", "/v1/rigs/{rig}/tests")];
    assert_eq!(
        value(
            "motorbench_api_requests_total",
            &[posts[0], posts[1], ("status", "201")]
        ),
        2.0
    );
    assert_eq!(
        value(
            "motorbench_api_requests_total",
            &[("route", "/v1/rigs"), ("status", "401")]
        ),
        1.0
    );
}
