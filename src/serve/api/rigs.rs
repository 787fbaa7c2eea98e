//! Endpoints about the daemon and its rigs: health, rig state, starting
//! a test, emergency stop and reset.

use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::StatusCode;
use axum::response::{IntoResponse, Response};
use axum::Json;

use super::bodies::{ErrorBody, Health, RigList, StartRequest, Started};
use super::{ApiError, Shared};
use crate::serve::state::RigStatus;

/// The health answer: `200` when healthy, else `503` with the same body,
/// so a load balancer or a plain `curl -f` sees the state.
pub fn health_answer(healthy: bool, rigs: Vec<String>) -> Response {
    let status = if healthy {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    let body = Health {
        healthy,
        version: env!("CARGO_PKG_VERSION").to_string(),
        rigs,
    };
    (status, Json(body)).into_response()
}

/// Whether the daemon is healthy (see the watchdog in `docs/daemon.md`).
#[utoipa::path(get, path = "/v1/health", tag = "daemon",
    responses(
        (status = 200, description = "healthy", body = Health),
        (status = 503, description = "a running test's supervisor is stuck or failed a safe-state command", body = Health),
    ))]
pub async fn health(State(d): Shared) -> Response {
    health_answer(d.healthy(), d.rig_names())
}

/// Every rig and its state.
#[utoipa::path(get, path = "/v1/rigs", tag = "rigs",
    responses((status = 200, description = "every rig", body = RigList)))]
pub async fn rigs(State(d): Shared) -> Json<RigList> {
    Json(RigList {
        rigs: d.rigs().await,
    })
}

/// One rig.
#[utoipa::path(get, path = "/v1/rigs/{rig}", tag = "rigs",
    params(("rig" = String, Path, description = "rig name (its configuration's file stem)")),
    responses(
        (status = 200, description = "the rig", body = RigStatus),
        (status = 404, description = "no such rig", body = ErrorBody),
    ))]
pub async fn rig(State(d): Shared, Path(name): Path<String>) -> Result<Json<RigStatus>, ApiError> {
    d.rig(&name)
        .await
        .map(Json)
        .ok_or_else(|| ApiError::not_found(format!("no rig `{name}`")))
}

/// Start a test on the rig: the configured plan, with `test` keys
/// replacing the configured `[test]` ones.
#[utoipa::path(post, path = "/v1/rigs/{rig}/tests", tag = "tests",
    params(("rig" = String, Path, description = "rig name")),
    request_body(content = Option<StartRequest>, description = "optional; overrides of the configuration's [test] keys"),
    responses(
        (status = 201, description = "started", body = Started),
        (status = 400, description = "the override is invalid (the key is named)", body = ErrorBody),
        (status = 404, description = "no such rig", body = ErrorBody),
        (status = 409, description = "the rig is busy (`busy`, with `running_test`) or latched (`tripped`, with `trip`)", body = ErrorBody),
        (status = 500, description = "the rig or the record could not be set up", body = ErrorBody),
        (status = 503, description = "the daemon is shutting down", body = ErrorBody),
    ))]
pub async fn start(
    State(d): Shared,
    Path(rig): Path<String>,
    body: Bytes,
) -> Result<Response, ApiError> {
    let request: StartRequest = if body.iter().all(u8::is_ascii_whitespace) {
        StartRequest::default()
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
    let body = Started {
        status: format!("/v1/tests/{id}"),
        events: format!("/v1/tests/{id}/events"),
        record: id.clone(),
        rig,
        id,
    };
    Ok((StatusCode::CREATED, Json(body)).into_response())
}

/// Emergency stop: the rig's test is stopped (safe state first) and the
/// rig latches until reset; an idle rig latches too.
#[utoipa::path(post, path = "/v1/rigs/{rig}/estop", tag = "rigs",
    params(("rig" = String, Path, description = "rig name")),
    responses(
        (status = 200, description = "stopped and latched", body = RigStatus),
        (status = 404, description = "no such rig", body = ErrorBody),
    ))]
pub async fn estop(State(d): Shared, Path(rig): Path<String>) -> Result<Json<RigStatus>, ApiError> {
    Ok(Json(d.emergency_stop(&rig, "API").await?))
}

/// Clear the rig's latch.
#[utoipa::path(post, path = "/v1/rigs/{rig}/reset", tag = "rigs",
    params(("rig" = String, Path, description = "rig name")),
    responses(
        (status = 200, description = "the latch is cleared", body = RigStatus),
        (status = 404, description = "no such rig", body = ErrorBody),
        (status = 409, description = "a test is still ending on the rig", body = ErrorBody),
    ))]
pub async fn reset(State(d): Shared, Path(rig): Path<String>) -> Result<Json<RigStatus>, ApiError> {
    Ok(Json(d.reset(&rig).await?))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn unhealthy_answers_503_with_the_same_body() {
        for (healthy, status) in [(true, 200), (false, 503)] {
            let r = health_answer(healthy, vec!["rig".into()]);
            assert_eq!(r.status().as_u16(), status);
            let body = axum::body::to_bytes(r.into_body(), 1 << 16).await.unwrap();
            let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
            assert_eq!(v["healthy"], healthy);
            assert_eq!(v["rigs"][0], "rig");
        }
    }
}
