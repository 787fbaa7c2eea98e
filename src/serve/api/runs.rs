//! Endpoints about tests: the list, one test's status, its live feed
//! (server-sent events) and abort.

use std::convert::Infallible;
use std::time::Duration;

use axum::extract::{Path, State};
use axum::response::sse::{Event as SseEvent, KeepAlive, Sse};
use axum::Json;
use futures_util::Stream;

use super::bodies::{Aborted, ErrorBody, TestList};
use super::{ApiError, Shared};
use crate::serve::jobs::TestStatus;

/// The tests this daemon process has run.
#[utoipa::path(get, path = "/v1/tests", tag = "tests",
    responses((status = 200, description = "every test of this process, oldest first", body = TestList)))]
pub async fn tests(State(d): Shared) -> Json<TestList> {
    Json(TestList {
        tests: d.tests().iter().map(|t| t.status()).collect(),
    })
}

/// A test's status.
#[utoipa::path(get, path = "/v1/tests/{id}", tag = "tests",
    params(("id" = String, Path, description = "test id (also the record's name)")),
    responses(
        (status = 200, description = "the test's status", body = TestStatus),
        (status = 404, description = "no such test in this daemon's run (see /v1/records)", body = ErrorBody),
    ))]
pub async fn test(State(d): Shared, Path(id): Path<String>) -> Result<Json<TestStatus>, ApiError> {
    let run = d.test(&id).ok_or_else(|| {
        ApiError::not_found(format!(
            "no test `{id}` in this daemon's run; see /v1/records"
        ))
    })?;
    Ok(Json(run.status()))
}

/// Abort a running test: the safe state first.
#[utoipa::path(post, path = "/v1/tests/{id}/abort", tag = "tests",
    params(("id" = String, Path, description = "test id")),
    responses(
        (status = 200, description = "stopped; what the supervisor did", body = Aborted),
        (status = 404, description = "no such test", body = ErrorBody),
        (status = 409, description = "the test has finished or is ending (`not_running`)", body = ErrorBody),
    ))]
pub async fn abort(State(d): Shared, Path(id): Path<String>) -> Result<Json<Aborted>, ApiError> {
    let stop = d.abort(&id).await?;
    Ok(Json(Aborted { id, stop }))
}

/// Progress as server-sent events: a `progress` event with the test's
/// status ten times a second, then one `done` event, then the end.
#[utoipa::path(get, path = "/v1/tests/{id}/events", tag = "tests",
    params(("id" = String, Path, description = "test id")),
    responses(
        (status = 200, description = "server-sent events: `progress` ten times a second, then one `done`; each event's data is the test's status (TestStatus) as JSON",
         content_type = "text/event-stream", body = String),
        (status = 404, description = "no such test in this daemon's run", body = ErrorBody),
    ))]
pub async fn events(
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
