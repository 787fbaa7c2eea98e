//! The HTTP/JSON control API (axum). Every path is under `/v1`; errors
//! are JSON `{"error": <code>, "message": <text>, …}` with a fitting
//! status. See `docs/daemon.md` for the reference with examples.
//!
//! The routes are registered together with their OpenAPI description
//! (`utoipa-axum`), so `/v1/openapi.json` lists exactly what is served.
//! Beside the API: `/metrics` (Prometheus text, [`crate::serve::metrics`])
//! and the status page at `/` ([`crate::serve::page`]).

pub mod bodies;
pub mod openapi;
pub mod records;
pub mod rigs;
pub mod runs;

use std::sync::Arc;

use axum::extract::{MatchedPath, Request, State};
use axum::http::{header, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use axum::routing::post;
use axum::{Json, Router};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::{require_token, Token};
use super::state::{Daemon, StartError, StopError};
use bodies::ErrorBody;

/// An error answer.
#[derive(Debug)]
pub struct ApiError {
    status: StatusCode,
    body: ErrorBody,
}

impl ApiError {
    fn new(status: StatusCode, code: &str, message: impl Into<String>) -> ApiError {
        ApiError {
            status,
            body: ErrorBody::new(code, message),
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
                body: ErrorBody {
                    running_test: Some(running.clone()),
                    ..ErrorBody::new(
                        "busy",
                        format!("the rig is running test {running}; one test at a time"),
                    )
                },
            },
            StartError::Tripped(latch) => ApiError {
                status: StatusCode::CONFLICT,
                body: ErrorBody {
                    trip: Some(latch.clone()),
                    ..ErrorBody::new(
                        "tripped",
                        format!(
                            "the rig is latched after a stop ({}); reset it first",
                            latch.message
                        ),
                    )
                },
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

/// The API's routes with their OpenAPI description.
fn documented() -> OpenApiRouter<Arc<Daemon>> {
    OpenApiRouter::with_openapi(openapi::base())
        .routes(routes!(rigs::health))
        .routes(routes!(rigs::rigs))
        .routes(routes!(rigs::rig))
        .routes(routes!(rigs::start))
        .routes(routes!(rigs::estop))
        .routes(routes!(rigs::reset))
        .routes(routes!(runs::tests))
        .routes(routes!(runs::test))
        .routes(routes!(runs::events))
        .routes(routes!(runs::abort))
        .routes(routes!(records::records))
        .routes(routes!(records::record))
        .routes(routes!(records::report))
        .routes(routes!(records::mcap))
        .routes(routes!(records::svg))
        .routes(routes!(records::residuals))
        .routes(routes!(openapi::document))
        .routes(routes!(super::metrics::metrics))
}

/// The OpenAPI document of the API, as served at `/v1/openapi.json`.
pub fn openapi_document() -> utoipa::openapi::OpenApi {
    let mut doc = documented().split_for_parts().1;
    openapi::finish(&mut doc);
    doc
}

/// The router; with `token`, every request but the status page's own
/// files must carry it.
pub fn router(daemon: Arc<Daemon>, token: Option<Token>) -> Router {
    let (api, mut doc) = documented().split_for_parts();
    openapi::finish(&mut doc);
    let api = api
        .layer(axum::Extension(Arc::new(doc)))
        .fallback(|| async { ApiError::not_found("no such endpoint") })
        .with_state(daemon.clone());
    with_token(api, token)
        .merge(super::page::router())
        .layer(axum::middleware::from_fn_with_state(daemon, count_request))
}

/// The stop endpoints alone (emergency stop and abort), for the reserved
/// connections served once the connection limit is reached; every other
/// request gets `503`.
pub fn stop_router(daemon: Arc<Daemon>, token: Option<Token>) -> Router {
    let api = Router::new()
        .route("/v1/rigs/{rig}/estop", post(rigs::estop))
        .route("/v1/tests/{id}/abort", post(runs::abort))
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

/// Middleware: count every answer by method, route (the path template,
/// not the path) and status for `/metrics`.
async fn count_request(State(d): Shared, request: Request, next: Next) -> Response {
    let method = request.method().as_str().to_string();
    let route = request
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let response = next.run(request).await;
    d.metrics()
        .api_request(method, route, response.status().as_u16());
    response
}

/// A file from the records directory as `content_type`, or a JSON error.
async fn record_file(
    d: &Daemon,
    file: &str,
    content_type: &'static str,
) -> Result<Response, ApiError> {
    let dir = d.index().lock().await.dir().to_path_buf();
    let bytes = tokio::fs::read(dir.join(file)).await.map_err(|err| {
        ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "io",
            format!("{file}: {err}"),
        )
    })?;
    Ok(([(header::CONTENT_TYPE, content_type)], bytes).into_response())
}
