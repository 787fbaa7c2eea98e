//! Metrics for the lab's monitoring, as Prometheus' text exposition
//! (OpenMetrics 1.0) at `/metrics`
//! (behind the same token as the API), with `prometheus-client`: tests
//! started and finished by outcome, tests stopped by cause, emergency
//! stops by source, each rig's state and winding temperature, records
//! written (count, bytes, messages, recorder waits for queue room), the
//! recorder's backlog now, requests and errors per bus and kind (timeouts,
//! exceptions, …; see [`super::link_tally`] for how a test's counts
//! become counters), the last test's duration, and API requests by route
//! and status.

use std::sync::atomic::AtomicU64;
use std::sync::Mutex;

use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use prometheus_client::encoding::text::encode;
use prometheus_client::encoding::EncodeLabelSet;
use prometheus_client::metrics::counter::Counter;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::gauge::Gauge;
use prometheus_client::registry::{Metric, Registry, Unit};

use super::link_tally::LinkGrowth;
use super::state::Daemon;

/// The content type of the exposition: OpenMetrics text, which
/// Prometheus scrapes (and `prometheus-client` writes).
pub const CONTENT_TYPE: &str = "application/openmetrics-text; version=1.0.0; charset=utf-8";

/// The rig states a rig can be in (the `state` label of `motorbench_rig_state`).
pub const RIG_STATES: [&str; 3] = ["idle", "running", "tripped"];

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RigLabel {
    rig: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct OutcomeLabels {
    rig: String,
    outcome: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct CauseLabels {
    rig: String,
    cause: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct SourceLabels {
    rig: String,
    source: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct StateLabels {
    rig: String,
    state: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct BusLabels {
    rig: String,
    bus: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct BusErrorLabels {
    rig: String,
    bus: String,
    kind: String,
}

#[derive(Clone, Debug, Hash, PartialEq, Eq, EncodeLabelSet)]
struct RequestLabels {
    method: String,
    route: String,
    status: u16,
}

type FloatGauge = Gauge<f64, AtomicU64>;

/// How a test ended, for the counters.
#[derive(Debug, Clone)]
pub struct TestEnd {
    /// The rig.
    pub rig: String,
    /// `completed`, `aborted`, `failed`.
    pub outcome: String,
    /// The supervisor's stop cause, when it stopped the test.
    pub stop_cause: Option<String>,
    /// Wall-clock duration, s.
    pub duration_s: f64,
    /// Size of the record's files, bytes.
    pub bytes: u64,
    /// Messages the recorder wrote.
    pub messages: u64,
    /// Times the recorder's queue was full.
    pub recorder_waits: u64,
}

/// A rig as a scrape sees it.
#[derive(Debug, Clone)]
pub struct RigSample {
    /// The rig.
    pub rig: String,
    /// `idle`, `running` or `tripped`.
    pub state: String,
    /// Estimated winding temperature, °C.
    pub winding_c: f64,
    /// Entries in the running test's recorder queue now (0 when idle).
    pub backlog: u64,
}

/// The daemon's metrics. See the module docs.
#[derive(Debug)]
pub struct Metrics {
    registry: Registry,
    tests_started: Family<RigLabel, Counter>,
    tests_finished: Family<OutcomeLabels, Counter>,
    tests_stopped: Family<CauseLabels, Counter>,
    emergency_stops: Family<SourceLabels, Counter>,
    rig_state: Family<StateLabels, Gauge>,
    winding: Family<RigLabel, FloatGauge>,
    records_written: Family<RigLabel, Counter>,
    record_bytes: Family<RigLabel, Counter>,
    recorded_messages: Family<RigLabel, Counter>,
    recorder_waits: Family<RigLabel, Counter>,
    recorder_backlog: Family<RigLabel, Gauge>,
    bus_requests: Family<BusLabels, Counter>,
    bus_errors: Family<BusErrorLabels, Counter>,
    last_duration: Family<RigLabel, FloatGauge>,
    api_requests: Family<RequestLabels, Counter>,
    alive_tasks: Gauge,
    /// Serialises scrapes (the rig gauges are set, then encoded).
    scrape: Mutex<()>,
}

impl Default for Metrics {
    fn default() -> Metrics {
        Metrics::new()
    }
}

impl Metrics {
    /// Every metric registered, none counted yet.
    pub fn new() -> Metrics {
        let mut r = Registry::with_prefix("motorbench");
        let celsius = || Some(Unit::Other("celsius".into()));
        Metrics {
            tests_started: registered(&mut r, "tests_started", "Tests started, per rig", None),
            tests_finished: registered(&mut r, "tests_finished", HELP_FINISHED, None),
            tests_stopped: registered(&mut r, "tests_stopped", HELP_STOPPED, None),
            emergency_stops: registered(&mut r, "emergency_stops", HELP_ESTOPS, None),
            rig_state: registered(&mut r, "rig_state", HELP_STATE, None),
            winding: registered(&mut r, "winding_temperature", HELP_WINDING, celsius()),
            records_written: registered(&mut r, "records_written", HELP_RECORDS, None),
            record_bytes: registered(&mut r, "record_written", HELP_BYTES, Some(Unit::Bytes)),
            recorded_messages: registered(&mut r, "recorded_messages", HELP_MESSAGES, None),
            recorder_waits: registered(&mut r, "recorder_queue_full", HELP_WAITS, None),
            recorder_backlog: registered(&mut r, "recorder_backlog", HELP_BACKLOG, None),
            bus_requests: registered(&mut r, "bus_requests", HELP_BUS_REQUESTS, None),
            bus_errors: registered(&mut r, "bus_errors", HELP_BUS_ERRORS, None),
            last_duration: registered(&mut r, "last_test_duration", HELP_LAST, Some(Unit::Seconds)),
            api_requests: registered(&mut r, "api_requests", HELP_REQUESTS, None),
            alive_tasks: registered(&mut r, "runtime_alive_tasks", HELP_TASKS, None),
            scrape: Mutex::new(()),
            registry: r,
        }
    }

    /// A test was started on `rig`.
    pub fn test_started(&self, rig: &str) {
        self.tests_started.get_or_create(&rig_label(rig)).inc();
    }

    /// A test ended.
    pub fn test_ended(&self, end: &TestEnd) {
        let rig = rig_label(&end.rig);
        self.tests_finished
            .get_or_create(&OutcomeLabels {
                rig: end.rig.clone(),
                outcome: end.outcome.clone(),
            })
            .inc();
        if let Some(cause) = &end.stop_cause {
            self.tests_stopped
                .get_or_create(&CauseLabels {
                    rig: end.rig.clone(),
                    cause: cause.clone(),
                })
                .inc();
        }
        self.records_written.get_or_create(&rig).inc();
        self.record_bytes.get_or_create(&rig).inc_by(end.bytes);
        self.recorded_messages
            .get_or_create(&rig)
            .inc_by(end.messages);
        self.recorder_waits
            .get_or_create(&rig)
            .inc_by(end.recorder_waits);
        self.last_duration.get_or_create(&rig).set(end.duration_s);
    }

    /// A test on `rig` used its links this much more since last counted.
    pub fn links_used(&self, rig: &str, growth: &[LinkGrowth]) {
        for g in growth {
            self.bus_requests
                .get_or_create(&BusLabels {
                    rig: rig.to_string(),
                    bus: g.link.clone(),
                })
                .inc_by(g.grown.requests);
            for (kind, n) in g.grown.by_kind() {
                self.bus_errors
                    .get_or_create(&BusErrorLabels {
                        rig: rig.to_string(),
                        bus: g.link.clone(),
                        kind: kind.to_string(),
                    })
                    .inc_by(n);
            }
        }
    }

    /// An emergency stop was requested on `rig` by `source`.
    pub fn emergency_stop(&self, rig: &str, source: &str) {
        self.emergency_stops
            .get_or_create(&SourceLabels {
                rig: rig.to_string(),
                source: source.to_string(),
            })
            .inc();
    }

    /// An API request was answered.
    pub fn api_request(&self, method: String, route: String, status: u16) {
        self.api_requests
            .get_or_create(&RequestLabels {
                method,
                route,
                status,
            })
            .inc();
    }

    /// The tasks alive in the daemon's runtime now (set before a scrape;
    /// a count that grows from test to test is a leaked task).
    pub fn set_alive_tasks(&self, tasks: usize) {
        self.alive_tasks
            .set(i64::try_from(tasks).unwrap_or(i64::MAX));
    }

    /// The text exposition, with each rig's state, winding temperature
    /// and recorder backlog as given.
    pub fn render(&self, rigs: &[RigSample]) -> String {
        let _scrape = self.scrape.lock().unwrap_or_else(|p| p.into_inner());
        for r in rigs {
            for s in RIG_STATES {
                self.rig_state
                    .get_or_create(&StateLabels {
                        rig: r.rig.clone(),
                        state: s.to_string(),
                    })
                    .set(i64::from(s == r.state));
            }
            let rig = rig_label(&r.rig);
            self.winding.get_or_create(&rig).set(r.winding_c);
            self.recorder_backlog
                .get_or_create(&rig)
                .set(i64::try_from(r.backlog).unwrap_or(i64::MAX));
        }
        let mut text = String::new();
        encode(&mut text, &self.registry).expect("writing to a String cannot fail");
        text
    }
}

const HELP_FINISHED: &str = "Tests finished, per rig and outcome (completed, aborted, failed)";
const HELP_STOPPED: &str = "Tests stopped by the safety supervisor, per rig and cause \
     (operator_abort, emergency_stop, limit, winding_temperature, stale_channel, clock_jump, bus_loss, \
     device_fault, …)";
const HELP_ESTOPS: &str =
    "Emergency stops requested, per rig and source (API, SIGUSR1), idle or not";
const HELP_STATE: &str =
    "1 for the rig's state (idle, running, tripped: latched after a stop), 0 for the others";
const HELP_WINDING: &str = "Estimated winding temperature, per rig";
const HELP_RECORDS: &str = "Records finished (report and index written), per rig";
const HELP_BYTES: &str = "Size of the records' files written, per rig";
const HELP_MESSAGES: &str = "MCAP messages the recorder wrote, per rig";
const HELP_WAITS: &str =
    "Times a sample batch waited for room in the recorder's queue (its backlog was full), per rig";
const HELP_BACKLOG: &str = "Entries waiting in the running test's recorder queue now (readings of \
     one instant, markers, events; 0 when no test runs), per rig";
const HELP_BUS_REQUESTS: &str =
    "Requests made on each bus (a Modbus call with its retries is one), per rig and bus";
const HELP_BUS_ERRORS: &str = "Bus errors, per rig, bus (its configured address, or \
     simulated:ROLE) and kind (timeout, exception, link_error, decode_error, lost, retry, \
     reconnect)";
const HELP_LAST: &str = "Wall-clock duration of the rig's last finished test";
const HELP_TASKS: &str = "Tasks alive in the daemon's async runtime now (the API's connections, \
     the running tests' tasks, the daemon's own), for finding leaked tasks";
const HELP_REQUESTS: &str =
    "API requests answered, per method, route (the path template) and status";

/// A new metric, registered in `registry` as `name` (with `unit`).
fn registered<M: Metric + Default + Clone>(
    registry: &mut Registry,
    name: &str,
    help: &str,
    unit: Option<Unit>,
) -> M {
    let metric = M::default();
    match unit {
        Some(unit) => registry.register_with_unit(name, help, unit, metric.clone()),
        None => registry.register(name, help, metric.clone()),
    }
    metric
}

fn rig_label(rig: &str) -> RigLabel {
    RigLabel {
        rig: rig.to_string(),
    }
}

/// Prometheus text exposition of the daemon's metrics.
#[utoipa::path(get, path = "/metrics", tag = "daemon",
    responses((status = 200, description = "OpenMetrics text (Prometheus' exposition format)",
               content_type = "application/openmetrics-text", body = String)))]
pub async fn metrics(State(d): State<std::sync::Arc<Daemon>>) -> Response {
    let mut rigs = Vec::new();
    for r in d.rigs().await {
        let run = r.running_test.as_deref().and_then(|id| d.test(id));
        if let Some(run) = &run {
            d.metrics().links_used(&r.name, &run.links().take_growth());
        }
        rigs.push(RigSample {
            backlog: run.map_or(0, |t| t.backlog().entries()),
            rig: r.name,
            state: r.state,
            winding_c: r.winding_c,
        });
    }
    d.metrics().set_alive_tasks(
        tokio::runtime::Handle::current()
            .metrics()
            .num_alive_tasks(),
    );
    (
        [(header::CONTENT_TYPE, CONTENT_TYPE)],
        d.metrics().render(&rigs),
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_show_in_the_text_format() {
        let m = Metrics::new();
        m.test_started("rig");
        m.test_ended(&TestEnd {
            rig: "rig".into(),
            outcome: "aborted".into(),
            stop_cause: Some("operator_abort".into()),
            duration_s: 2.5,
            bytes: 1000,
            messages: 42,
            recorder_waits: 0,
        });
        m.emergency_stop("rig", "API");
        m.api_request("GET".into(), "/v1/rigs".into(), 200);
        m.set_alive_tasks(9);
        m.links_used(
            "rig",
            &[LinkGrowth {
                link: "tcp:10.0.0.5:502".into(),
                grown: motorbench_drivers::LinkCounts {
                    requests: 40,
                    timeouts: 3,
                    ..Default::default()
                },
            }],
        );
        let text = m.render(&[RigSample {
            rig: "rig".into(),
            state: "tripped".into(),
            winding_c: 41.5,
            backlog: 7,
        }]);
        for line in [
            "motorbench_tests_started_total{rig=\"rig\"} 1",
            "motorbench_tests_finished_total{rig=\"rig\",outcome=\"aborted\"} 1",
            "motorbench_tests_stopped_total{rig=\"rig\",cause=\"operator_abort\"} 1",
            "motorbench_emergency_stops_total{rig=\"rig\",source=\"API\"} 1",
            "motorbench_rig_state{rig=\"rig\",state=\"tripped\"} 1",
            "motorbench_rig_state{rig=\"rig\",state=\"idle\"} 0",
            "motorbench_winding_temperature_celsius{rig=\"rig\"} 41.5",
            "motorbench_record_written_bytes_total{rig=\"rig\"} 1000",
            "motorbench_last_test_duration_seconds{rig=\"rig\"} 2.5",
            "motorbench_api_requests_total{method=\"GET\",route=\"/v1/rigs\",status=\"200\"} 1",
            "motorbench_recorder_backlog{rig=\"rig\"} 7",
            "motorbench_runtime_alive_tasks 9",
            "motorbench_bus_requests_total{rig=\"rig\",bus=\"tcp:10.0.0.5:502\"} 40",
            "motorbench_bus_errors_total{rig=\"rig\",bus=\"tcp:10.0.0.5:502\",kind=\"timeout\"} 3",
            "motorbench_bus_errors_total{rig=\"rig\",bus=\"tcp:10.0.0.5:502\",kind=\"exception\"} 0",
        ] {
            assert!(text.lines().any(|l| l == line), "{line} missing in\n{text}");
        }
        assert!(text.ends_with("# EOF\n"), "{text}");
    }
}
