//! Endpoints about records: the index, one entry, and the record's files
//! (report, MCAP, plot).

use axum::body::{Body, Bytes};
use axum::extract::{Path, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;

use super::bodies::{ErrorBody, RecordList};
use super::{record_file, ApiError, Shared};
use crate::serve::records_index::IndexEntry;
use crate::serve::state::Daemon;

/// The media type of an MCAP file.
pub const MCAP_MEDIA_TYPE: &str = "application/vnd.mcap";

/// The records index, newest first.
#[utoipa::path(get, path = "/v1/records", tag = "records",
    responses((status = 200, description = "the index, newest first", body = RecordList)))]
pub async fn records(State(d): Shared) -> Json<RecordList> {
    let index = d.index().lock().await;
    let mut list: Vec<IndexEntry> = index.entries().to_vec();
    list.reverse();
    Json(RecordList { records: list })
}

async fn entry(d: &Daemon, name: &str) -> Result<IndexEntry, ApiError> {
    d.index()
        .lock()
        .await
        .get(name)
        .cloned()
        .ok_or_else(|| ApiError::not_found(format!("no record `{name}`")))
}

/// One record's index entry.
#[utoipa::path(get, path = "/v1/records/{name}", tag = "records",
    params(("name" = String, Path, description = "record name (the test id)")),
    responses(
        (status = 200, description = "the index entry", body = IndexEntry),
        (status = 404, description = "no such record", body = ErrorBody),
    ))]
pub async fn record(
    State(d): Shared,
    Path(name): Path<String>,
) -> Result<Json<IndexEntry>, ApiError> {
    Ok(Json(entry(&d, &name).await?))
}

/// The record's report (`NAME.report.json`).
#[utoipa::path(get, path = "/v1/records/{name}/report", tag = "records",
    params(("name" = String, Path, description = "record name")),
    responses(
        (status = 200, description = "the report (see docs/data-contract.md)", body = Object),
        (status = 404, description = "no such record, or it has no report (yet)", body = ErrorBody),
        (status = 500, description = "the file could not be read", body = ErrorBody),
    ))]
pub async fn report(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    let e = entry(&d, &name).await?;
    listed_file(&d, &e, e.report.as_deref(), "report", "application/json").await
}

/// The entry's file `file` (`None`: not written, or not yet) as
/// `content_type`.
async fn listed_file(
    d: &Daemon,
    e: &IndexEntry,
    file: Option<&str>,
    what: &str,
    content_type: &'static str,
) -> Result<Response, ApiError> {
    let file = file.ok_or_else(|| {
        ApiError::not_found(format!(
            "record `{}` has no {what} (yet): {}",
            e.name,
            e.outcome.as_str()
        ))
    })?;
    record_file(d, file, content_type).await
}

/// The record's plot (`NAME.svg`), as listed in its index entry.
#[utoipa::path(get, path = "/v1/records/{name}/svg", tag = "records",
    params(("name" = String, Path, description = "record name")),
    responses(
        (status = 200, description = "the record's plot", content_type = "image/svg+xml", body = String),
        (status = 404, description = "no such record, or it has no plot (yet)", body = ErrorBody),
        (status = 500, description = "the file could not be read", body = ErrorBody),
    ))]
pub async fn svg(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    let e = entry(&d, &name).await?;
    listed_file(&d, &e, e.svg.as_deref(), "plot", "image/svg+xml").await
}

/// The record's residual plot (`NAME.residuals.svg`: where the model
/// misses the measurement), as listed in its index entry.
#[utoipa::path(get, path = "/v1/records/{name}/residuals", tag = "records",
    params(("name" = String, Path, description = "record name")),
    responses(
        (status = 200, description = "the residual plot", content_type = "image/svg+xml", body = String),
        (status = 404, description = "no such record, or it has no residual plot (not diagnosed, or not yet)", body = ErrorBody),
        (status = 500, description = "the file could not be read", body = ErrorBody),
    ))]
pub async fn residuals(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
    let e = entry(&d, &name).await?;
    let file = e.residuals_svg.as_deref();
    listed_file(&d, &e, file, "residual plot", "image/svg+xml").await
}

/// The record's MCAP file, streamed.
#[utoipa::path(get, path = "/v1/records/{name}/mcap", tag = "records",
    params(("name" = String, Path, description = "record name")),
    responses(
        (status = 200, description = "the MCAP file (also while the test runs: what is flushed so far)", content_type = "application/vnd.mcap", body = Vec<u8>),
        (status = 404, description = "no such record, or its file is gone", body = ErrorBody),
    ))]
pub async fn mcap(State(d): Shared, Path(name): Path<String>) -> Result<Response, ApiError> {
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
            (header::CONTENT_TYPE, MCAP_MEDIA_TYPE.to_string()),
            (
                header::CONTENT_DISPOSITION,
                format!("attachment; filename=\"{}\"", e.mcap),
            ),
        ],
        Body::from_stream(chunks),
    )
        .into_response())
}
