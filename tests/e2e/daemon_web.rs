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

use common::daemon::{finished, python_script, start_with_token, wait_test, Metrics, WEB_TOKEN};

/// A metric's label: name and value.
type Label<'a> = (&'a str, &'a str);

/// The exchanges made, for the document check.
#[derive(Default)]
struct Exchanges(Vec<Value>);

/// `route` with its path parameter (`{…}`, at most one) set to `value`.
fn fill(route: &str, value: &str) -> String {
    match (route.find('{'), route.find('}')) {
        (Some(a), Some(b)) => format!("{}{value}{}", &route[..a], &route[b + 1..]),
        _ => route.to_string(),
    }
}

impl Exchanges {
    /// `method` on `route` with its parameter `value`, with an optional
    /// JSON body; the answer, noted.
    async fn call(
        &mut self,
        c: &Client,
        method: &str,
        route: &str,
        value: &str,
        body: Option<Value>,
    ) -> Reply {
        let path = fill(route, value);
        let r = c
            .request(method.parse().unwrap(), &path, body.as_ref())
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

    /// [`Exchanges::call`] without a body, which must answer `status`.
    async fn expect(
        &mut self,
        c: &Client,
        method: &str,
        route: &str,
        value: &str,
        status: u16,
    ) -> Reply {
        let r = self.call(c, method, route, value, None).await;
        let body = String::from_utf8_lossy(&r.body);
        assert_eq!(r.status, status, "{method} {route} ({value}): {body}");
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
        .expect(&c, "GET", "/v1/openapi.json", "", 200)
        .await
        .json();
    assert!(
        doc["openapi"].as_str().unwrap().starts_with("3."),
        "{}",
        doc["openapi"]
    );
    let r = ex.expect(&anon, "GET", "/v1/rigs", "", 401).await;
    assert_eq!(r.json()["error"], "unauthorized");

    let health = ex.expect(&c, "GET", "/v1/health", "", 200).await;
    assert_eq!(health.json()["healthy"], true);
    ex.expect(&c, "GET", "/v1/rigs", "", 200).await;
    ex.expect(&c, "GET", "/v1/rigs/{rig}", "rig", 200).await;
    ex.expect(&c, "GET", "/v1/rigs/{rig}", "nope", 404).await;

    // A short test, followed to its end.
    let start = "/v1/rigs/{rig}/tests";
    let short = json!({"test": {"levels_V": [60, 248], "coastdown": false}});
    let r = ex.call(&c, "POST", start, "rig", Some(short.clone())).await;
    assert_eq!(r.status, 201, "{}", String::from_utf8_lossy(&r.body));
    let id = r.json()["id"].as_str().unwrap().to_string();
    let r = ex.call(&c, "POST", start, "rig", Some(short)).await;
    assert_eq!(r.status, 409);
    assert_eq!(r.json()["running_test"], id.as_str());
    ex.expect(&c, "POST", start, "nope", 404).await;
    ex.expect(&c, "GET", "/v1/tests", "", 200).await;
    ex.expect(&c, "GET", "/v1/tests/{id}", &id, 200).await;
    ex.expect(&c, "GET", "/v1/tests/{id}", "nope", 404).await;
    ex.expect(&c, "GET", "/v1/tests/{id}/events", "nope", 404)
        .await;
    let events = ex
        .expect(&c, "GET", "/v1/tests/{id}/events", &id, 200)
        .await;
    assert_eq!(events.content_type.as_deref(), Some("text/event-stream"));
    assert!(String::from_utf8_lossy(&events.body).contains("event: done"));
    wait_test(&c, &id, finished).await;

    // The record and its files, each with its own media type.
    ex.expect(&c, "GET", "/v1/records", "", 200).await;
    let entry = ex
        .expect(&c, "GET", "/v1/records/{name}", &id, 200)
        .await
        .json();
    assert_eq!(entry["outcome"], "completed");
    ex.expect(&c, "GET", "/v1/records/{name}/report", &id, 200)
        .await;
    assert_eq!(
        entry["svg"],
        format!("{id}.svg"),
        "the index lists the plot"
    );
    let svg = ex
        .expect(&c, "GET", "/v1/records/{name}/svg", &id, 200)
        .await;
    assert_eq!(svg.content_type.as_deref(), Some("image/svg+xml"));
    assert!(
        String::from_utf8_lossy(&svg.body).contains("<svg"),
        "an SVG"
    );
    assert_eq!(entry["residuals_svg"], format!("{id}.residuals.svg"));
    let residuals = ex
        .expect(&c, "GET", "/v1/records/{name}/residuals", &id, 200)
        .await;
    assert_eq!(residuals.content_type.as_deref(), Some("image/svg+xml"));
    let mcap = ex
        .expect(&c, "GET", "/v1/records/{name}/mcap", &id, 200)
        .await;
    assert_eq!(mcap.content_type.as_deref(), Some("application/vnd.mcap"));
    assert!(mcap.body.starts_with(b"\x89MCAP"), "an MCAP file");
    for route in ["", "/report", "/svg", "/residuals", "/mcap"] {
        let route = format!("/v1/records/{{name}}{route}");
        ex.expect(&c, "GET", &route, "nope", 404).await;
    }

    // Aborts: of a finished test, of none, of a running one.
    let abort = "/v1/tests/{id}/abort";
    ex.expect(&c, "POST", abort, &id, 409).await;
    ex.expect(&c, "POST", abort, "nope", 404).await;
    let bad = json!({"test": {"levels_V": [900]}});
    let r = ex.call(&c, "POST", start, "rig", Some(bad)).await;
    assert_eq!(r.status, 400, "{}", String::from_utf8_lossy(&r.body));
    let r = ex.expect(&c, "POST", start, "rig", 201).await;
    let id2 = r.json()["id"].as_str().unwrap().to_string();
    wait_test(&c, &id2, |s| {
        s["segment"]["index"].as_u64().unwrap_or(0) >= 1
    })
    .await;
    let r = ex.expect(&c, "POST", abort, &id2, 200).await;
    assert_eq!(r.json()["stop"]["kind"], "operator_abort");
    wait_test(&c, &id2, finished).await;

    // Emergency stop, refused start, reset.
    let r = ex
        .expect(&c, "POST", "/v1/rigs/{rig}/estop", "rig", 200)
        .await;
    assert_eq!(r.json()["state"], "tripped");
    let r = ex.expect(&c, "POST", start, "rig", 409).await;
    assert_eq!(r.json()["error"], "tripped");
    ex.expect(&c, "POST", "/v1/rigs/{rig}/reset", "rig", 200)
        .await;
    ex.expect(&c, "POST", "/v1/rigs/{rig}/estop", "nope", 404)
        .await;
    ex.expect(&c, "POST", "/v1/rigs/{rig}/reset", "nope", 404)
        .await;
    let metrics = ex.expect(&c, "GET", "/metrics", "", 200).await;

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
    let samples = Metrics::parse(&metrics.body, dir.path());
    let value = |name: &str, labels: &[(&str, &str)]| samples.value(name, labels);
    let rig = ("rig", "rig");
    let post_201 = [
        ("method", "POST"),
        ("route", "/v1/rigs/{rig}/tests"),
        ("status", "201"),
    ];
    let (completed, aborted) = (("outcome", "completed"), ("outcome", "aborted"));
    let (by_operator, by_api) = (("cause", "operator_abort"), ("source", "API"));
    let (idle, tripped) = (("state", "idle"), ("state", "tripped"));
    let refused = [("route", "/v1/rigs"), ("status", "401")];
    let exact: [(&str, &[Label], f64); 10] = [
        ("tests_started_total", &[rig], 2.0),
        ("tests_finished_total", &[rig, completed], 1.0),
        ("tests_finished_total", &[rig, aborted], 1.0),
        ("tests_stopped_total", &[rig, by_operator], 1.0),
        ("emergency_stops_total", &[rig, by_api], 1.0),
        ("rig_state", &[rig, idle], 1.0),
        ("rig_state", &[rig, tripped], 0.0),
        ("records_written_total", &[rig], 2.0),
        ("api_requests_total", &post_201, 2.0),
        ("api_requests_total", &refused, 1.0),
    ];
    for (name, labels, want) in exact {
        assert_eq!(value(name, labels), want, "{name} {labels:?}");
    }
    let at_least: [(&str, f64); 3] = [
        ("record_written_bytes_total", 1000.0),
        ("recorded_messages_total", 100.0),
        ("last_test_duration_seconds", 0.0),
    ];
    for (name, above) in at_least {
        assert!(value(name, &[rig]) > above, "{name}");
    }
    let winding = value("winding_temperature_celsius", &[rig]);
    assert!((20.0..200.0).contains(&winding), "winding {winding}");
    // No test runs: the recorder's queue is empty, and it is shown.
    assert_eq!(samples.count("recorder_backlog", &[rig]), 1);
    assert_eq!(value("recorder_backlog", &[rig]), 0.0);
}
