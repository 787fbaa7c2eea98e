//! The HTTP/JSON control API (axum). Every path is under `/v1`; errors
//! are JSON `{"error": <code>, "message": <text>, …}` with a fitting
//! status. See `docs/daemon.md` for the reference with examples.

use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::{header, StatusCode};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use futures_util::Stream;
use serde::Deserialize;
use serde_json::json;

use super::auth::{require_token, Token};
use super::records_index::IndexEntry;
use super::state::{Daemon, StartError, StopError};

/// An error answer.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    body: serde_json::Value,
}

impl ApiError {
    fn new(status: StatusCode, code: &str, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            body: json!({"error": code, "message": message.into()}),
        }
    }

    fn not_found(message: impl Into<String>) -> ApiError {
        ApiError::new(StatusCode::NOT_FOUND, "not_found", message)
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        (self.status, Json(self.body)).into_response()
    }
}

impl From<StopError> for ApiError {
    fn from(e: StopError) -> ApiError {
        match e {
            StopError::NotFound(m) => ApiError::not_found(m),
            StopError::NotRunning(m) => ApiError::new(StatusCode::CONFLICT, "not_running", m),
        }
    }
}

impl From<StartError> for ApiError {
    fn from(e: StartError) -> ApiError {
        match e {
            StartError::NoSuchRig(r) => ApiError::not_found(format!("no rig `{r}`")),
            StartError::Busy { running } => ApiError {
                status: StatusCode::CONFLICT,
                body: json!({
                    "error": "busy",
                    "message": format!("the rig is running test {running}; one test at a time"),
                    "running_test": running,
                }),
            },
            StartError::Tripped(latch) => ApiError {
                status: StatusCode::CONFLICT,
                body: json!({
                    "error": "tripped",
                    "message": format!("the rig is latched after a stop ({}); reset it first", latch.message),
                    "trip": latch,
                }),
            },
            StartError::Stopping => ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "stopping",
                "the daemon is shutting down",
            ),
            StartError::BadRequest(m) => ApiError::new(StatusCode::BAD_REQUEST, "bad_request", m),
            StartError::Setup(e) => ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                "setup_failed",
                e.to_string(),
            ),
        }
    }
}

type Shared = State<Arc<Daemon>>;

/// The router; with `token`, every request must carry it.
pub fn router(daemon: Arc<Daemon>, token: Option<Token>) -> Router {
    let api = Router::new()
        .route("/v1/health", get(health))
        .route("/v1/rigs", get(rigs))
        .route("/v1/rigs/{rig}", get(rig))
        .route("/v1/rigs/{rig}/tests", post(start))
        .route("/v1/rigs/{rig}/estop", post(estop))
        .route("/v1/rigs/{rig}/reset", post(reset))
        .route("/v1/tests", get(tests))
        .route("/v1/tests/{id}", get(test))
        .route("/v1/tests/{id}/events", get(events))
        .route("/v1/tests/{id}/abort", post(abort))
        .route("/v1/records", get(records))
        .route("/v1/records/{name}", get(record))
        .route("/v1/records/{name}/report", get(report))
        .route("/v1/records/{name}/mcap", get(mcap))
        .fallback(|| async { ApiError::not_found("no such endpoint") })
        .with_state(daemon);
    with_token(api, token)
}

/// The stop endpoints alone (emergency stop and abort), for the reserved
/// connections served once the connection limit is reached; every other
/// request gets `503`.
pub fn stop_router(daemon: Arc<Daemon>, token: Option<Token>) -> Router {
    let api = Router::new()
        .route("/v1/rigs/{rig}/estop", post(estop))
        .route("/v1/tests/{id}/abort", post(abort))
        .fallback(|| async {
            ApiError::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "too_many_connections",
                "every API connection is in use: this reserved connection serves only \
                 POST /v1/rigs/{rig}/estop and POST /v1/tests/{id}/abort",
            )
        })
        .with_state(daemon);
    with_token(api, token)
}

fn with_token(api: Router, token: Option<Token>) -> Router {
    match token {
        Some(t) => api.layer(axum::middleware::from_fn_with_state(t, require_token)),
        None => api,
    }
}

async fn health(State(d): Shared) -> Json<serde_json::Value> {
    Json(json!({
        "healthy": d.healthy(),
        "version": env!("CARGO_PKG_VERSION"),
        "rigs": d.rig_names(),
    }))
}

async fn rigs(State(d): Shared) -> Json<serde_json::Value> {
    Json(json!({"rigs": d.rigs().await}))
}

async fn rig(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    let rig = d
        .rig(&name)
        .await
        .ok_or_else(|| ApiError::not_found(format!("no rig `{name}`")))?;
    Ok(Json(rig).into_response())
}

/// Body of a start request (optional).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct StartRequest {
    /// Keys of the configuration's `[test]` to override.
    #[serde(default)]
    test: Option<serde_json::Map<String, serde_json::Value>>,
}

async fn start(
    State(d): Shared,
    Path(rig): Path<String>,
    body: Bytes,
) -> Result<Response, ApiError> {
    let request: StartRequest = if body.iter().all(u8::is_ascii_whitespace) {
        StartRequest { test: None }
    } else {
        serde_json::from_slice(&body).map_err(|e| {
            ApiError::new(
                StatusCode::BAD_REQUEST,
                "bad_request",
                format!("request body: {e}"),
            )
        })?
    };
    let run = d.start(&rig, request.test.as_ref()).await?;
    let id = run.id();
    let body = json!({
        "id": id,
        "rig": rig,
        "record": id,
        "status": format!("/v1/tests/{id}"),
        "events": format!("/v1/tests/{id}/events"),
    });
    Ok((StatusCode::CREATED, Json(body)).into_response())
}

async fn estop(State(d): Shared, Path(rig): Path<String>) -> Result<Response, ApiError> {
    Ok(Json(d.emergency_stop(&rig, "API").await?).into_response())
}

async fn reset(State(d): Shared, Path(rig): Path<String>) -> Result<Response, ApiError> {
    Ok(Json(d.reset(&rig).await?).into_response())
}

async fn tests(State(d): Shared) -> Json<serde_json::Value> {
    let tests: Vec<_> = d.tests().iter().map(|t| t.status()).collect();
    Json(json!({"tests": tests}))
}

async fn test(State(d): Shared, Path(id): Path<String>) -> Result<Response, ApiError> {
    let run = d.test(&id).ok_or_else(|| {
        ApiError::not_found(format!(
            "no test `{id}` in this daemon's run; see /v1/records"
        ))
    })?;
    Ok(Json(run.status()).into_response())
}

async fn abort(State(d): Shared, Path(id): Path<String>) -> Result<Response, ApiError> {
    let stop = d.abort(&id).await?;
    Ok(Json(json!({"id": id, "stop": stop})).into_response())
}

/// Progress as server-sent events: a `progress` event with the test's
/// status ten times a second, then one `done` event, then the end.
async fn events(
    State(d): Shared,
    Path(id): Path<String>,
) -> Result<Sse<impl Stream<Item = Result<SseEvent, Infallible>>>, ApiError> {
    let run = d
        .test(&id)
        .ok_or_else(|| ApiError::not_found(format!("no test `{id}` in this daemon's run")))?;
    let mut ticker = tokio::time::interval(Duration::from_millis(100));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    let stream =
        futures_util::stream::unfold((run, ticker, false), |(run, mut ticker, done)| async move {
            if done {
                return None;
            }
            if !run.finished() {
                tokio::select! {
                    _ = ticker.tick() => {}
                    _ = run.wait_finished() => {}
                }
            }
            let status = run.status();
            let finished = run.finished();
            let event = SseEvent::default()
                .event(if finished { "done" } else { "progress" })
                .json_data(&status)
                .expect("a status serialises");
            Some((Ok(event), (run, ticker, finished)))
        });
    Ok(Sse::new(stream).keep_alive(KeepAlive::default()))
}

async fn records(State(d): Shared) -> Json<serde_json::Value> {
    let index = d.index().lock().await;
    let mut list: Vec<IndexEntry> = index.entries().to_vec();
    list.reverse();
    Json(json!({"records": list}))
}

async fn entry(d: &Daemon, name: &str) -> Result<IndexEntry, ApiError> {
    d.index()
        .lock()
        .await
        .get(name)
        .cloned()
        .ok_or_else(|| ApiError::not_found(format!("no record `{name}`")))
}

async fn record(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    Ok(Json(entry(&d, &name).await?).into_response())
}

async fn report(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    let e = entry(&d, &name).await?;
    let file = e.report.ok_or_else(|| {
        ApiError::not_found(format!(
            "record `{name}` has no report (yet): {:?}",
            e.outcome
        ))
    })?;
    let dir = d.index().lock().await.dir().to_path_buf();
    let text = tokio::fs::read(dir.join(&file)).await.map_err(|err| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "io",
            format!("{file}: {err}"),
        )
    })?;
    Ok(([(header::CONTENT_TYPE, "application/json")], text).into_response())
}

async fn mcap(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    let e = entry(&d, &name).await?;
    let dir = d.index().lock().await.dir().to_path_buf();
    let file = tokio::fs::File::open(dir.join(&e.mcap))
        .await
        .map_err(|err| {
            ApiError::new(
                StatusCode::NOT_FOUND,
                "not_found",
                format!("{}: {err}", e.mcap),
            )
        })?;
    let chunks = futures_util::stream::unfold(Some(file), |file| async move {
        use tokio::io::AsyncReadExt;
        let mut file = file?;
        let mut buf = vec![0u8; 64 * 1024];
        match file.read(&mut buf).await {
            Ok(0) => None,
            Ok(n) => {
                buf.truncate(n);
                Some((Ok::<_, std::io::Error>(Bytes::from(buf)), Some(file)))
            }
            // Report the error once, then end the body.
            Err(e) => Some((Err(e), None)),
        }
    });
    Ok((
        [
            (header::CONTENT_TYPE, "application/octet-stream".to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{}\"", e.mcap),
            ),
        ],
        Body::from_stream(chunks),
    )
        .into_response())
}
