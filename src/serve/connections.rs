//! The API's connections: one accept loop over the TCP or Unix listener,
//! each connection served by hyper (HTTP/1.1) with
//!
//! - a header timeout, which is also the idle timeout of a kept-alive
//!   connection (hyper starts it whenever it waits for a request head);
//! - a body timeout: a request's body must arrive within the same time;
//! - a limit on open connections, kept below the process's descriptor
//!   limit (`RLIMIT_NOFILE`), so idle or half-sent connections cannot
//!   starve the rigs, the records and the API of descriptors;
//! - a few reserved connections beyond the limit that serve only the stop
//!   endpoints (emergency stop and abort), one request each, so a stop
//!   through the API still works while the limit is saturated. Beyond
//!   those, a connection gets a `503` and is closed at once.
//!
//! The signal path (`SIGUSR1`: emergency stop on every rig) needs no
//! connection at all; see [`super::serve`].

use std::io;
use std::sync::Arc;
use std::time::Duration;

use axum::body::Body;
use axum::extract::{Request, State};
use axum::http::StatusCode;
use axum::middleware::{from_fn_with_state, Next};
use axum::response::{IntoResponse, Response};
use axum::Router;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite};
use tokio::sync::{watch, OwnedSemaphorePermit, Semaphore};

/// Default header (and idle, and body) timeout.
pub const DEFAULT_HEADER_TIMEOUT: Duration = Duration::from_secs(10);

/// Default connection limit, before the descriptor limit lowers it.
pub const DEFAULT_MAX_CONNECTIONS: usize = 256;

/// Connections served beyond the limit, for the stop endpoints only.
pub const RESERVED_STOP_CONNECTIONS: usize = 4;

/// Descriptors kept for everything else the daemon opens (records, the
/// index, device links, the reserved connections), out of `RLIMIT_NOFILE`.
const DESCRIPTORS_KEPT: u64 = 64;

/// Largest request body read, bytes (a test override is a few hundred).
const MAX_BODY_BYTES: usize = 1 << 20;

/// Header timeout of a reserved stop connection.
const RESERVED_HEADER_TIMEOUT: Duration = Duration::from_secs(2);

/// The connection policy.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConnectionLimits {
    /// Open connections served with the whole API.
    pub max: usize,
    /// Header, idle and body timeout.
    pub header_timeout: Duration,
}

impl ConnectionLimits {
    /// `requested` connections (default [`DEFAULT_MAX_CONNECTIONS`]),
    /// lowered to fit under `nofile` descriptors (the soft
    /// `RLIMIT_NOFILE`; `None`: unlimited), at least one.
    pub fn new(requested: Option<usize>, header_timeout: Duration, nofile: Option<u64>) -> Self {
        let requested = requested.unwrap_or(DEFAULT_MAX_CONNECTIONS);
        let fits = nofile.map_or(usize::MAX, |n| {
            usize::try_from(n.saturating_sub(DESCRIPTORS_KEPT)).unwrap_or(usize::MAX)
        });
        ConnectionLimits {
            max: requested.min(fits).max(1),
            header_timeout,
        }
    }
}

/// The process's soft descriptor limit (`RLIMIT_NOFILE`); `None` when
/// unlimited.
pub fn descriptor_limit() -> Option<u64> {
    rustix::process::getrlimit(rustix::process::Resource::Nofile).current
}

/// A bound listener.
pub enum Listener {
    /// TCP.
    Tcp(tokio::net::TcpListener),
    /// A Unix socket.
    Unix(tokio::net::UnixListener),
}

/// What a connection is served with.
#[derive(Clone)]
pub struct Apps {
    /// The whole API.
    pub full: Router,
    /// The stop endpoints only, for the reserved connections.
    pub stops: Router,
}

/// Serve connections on `listener` until `stop` turns true; then ask
/// every connection to close after its current request, and return once
/// all have (or after `drain`, leaving the rest to the process's end).
pub async fn serve_connections(
    listener: Listener,
    apps: Apps,
    limits: ConnectionLimits,
    mut stop: watch::Receiver<bool>,
    drain: Duration,
) {
    let full = Arc::new(Semaphore::new(limits.max));
    let reserved = Arc::new(Semaphore::new(RESERVED_STOP_CONNECTIONS));
    let apps = Apps {
        full: apps
            .full
            .layer(from_fn_with_state(limits.header_timeout, read_body)),
        stops: apps
            .stops
            .layer(from_fn_with_state(RESERVED_HEADER_TIMEOUT, read_body)),
    };
    let mut warned_full = false;
    loop {
        let accepted = tokio::select! {
            _ = stopped(&mut stop) => break,
            a = accept(&listener) => a,
        };
        let conn = match accepted {
            Ok(c) => c,
            Err(e) => {
                // Out of descriptors (or a transient error): do not spin.
                tracing::warn!("accepting an API connection failed: {e}");
                tokio::time::sleep(Duration::from_millis(100)).await;
                continue;
            }
        };
        let (app, permit, timeout, keep_alive) = match full.clone().try_acquire_owned() {
            Ok(p) => {
                warned_full = false;
                (apps.full.clone(), p, limits.header_timeout, true)
            }
            Err(_) => {
                if !warned_full {
                    tracing::warn!(
                        "{} API connections open (the limit): new ones serve only \
                         the stop endpoints until some close",
                        limits.max
                    );
                    warned_full = true;
                }
                match reserved.clone().try_acquire_owned() {
                    Ok(p) => (apps.stops.clone(), p, RESERVED_HEADER_TIMEOUT, false),
                    Err(_) => {
                        conn.refuse();
                        continue;
                    }
                }
            }
        };
        let stop = stop.clone();
        match conn {
            Conn::Tcp(s) => {
                tokio::spawn(serve_one(s, app, timeout, keep_alive, stop, permit));
            }
            Conn::Unix(s) => {
                tokio::spawn(serve_one(s, app, timeout, keep_alive, stop, permit));
            }
        }
    }
    // Every permit back: every connection closed.
    let all = u32::try_from(limits.max).unwrap_or(u32::MAX);
    let _ = tokio::time::timeout(drain, full.acquire_many(all)).await;
}

enum Conn {
    Tcp(tokio::net::TcpStream),
    Unix(tokio::net::UnixStream),
}

impl Conn {
    /// Answer `503` without waiting (a fresh socket's buffer takes it)
    /// and close.
    fn refuse(self) {
        let body = serde_json::json!({
            "error": "too_many_connections",
            "message": "every API connection is in use; try again, or stop the rigs with SIGUSR1",
        })
        .to_string();
        let reply = format!(
            "HTTP/1.1 503 Service Unavailable\r\ncontent-type: application/json\r\n\
             connection: close\r\ncontent-length: {}\r\n\r\n{body}",
            body.len()
        );
        let _ = match &self {
            Conn::Tcp(s) => s.try_write(reply.as_bytes()),
            Conn::Unix(s) => s.try_write(reply.as_bytes()),
        };
    }
}

async fn accept(listener: &Listener) -> io::Result<Conn> {
    match listener {
        Listener::Tcp(l) => l.accept().await.map(|(s, _)| Conn::Tcp(s)),
        Listener::Unix(l) => l.accept().await.map(|(s, _)| Conn::Unix(s)),
    }
}

async fn serve_one<I>(
    io: I,
    app: Router,
    header_timeout: Duration,
    keep_alive: bool,
    mut stop: watch::Receiver<bool>,
    _permit: OwnedSemaphorePermit,
) where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout)
        .keep_alive(keep_alive);
    let conn = builder.serve_connection(TokioIo::new(io), TowerToHyperService::new(app));
    let mut conn = std::pin::pin!(conn);
    tokio::select! {
        r = conn.as_mut() => {
            if let Err(e) = r {
                tracing::debug!("API connection closed: {e}");
            }
        }
        _ = stopped(&mut stop) => {
            conn.as_mut().graceful_shutdown();
            let _ = conn.await;
        }
    }
}

/// Resolves once `stop` is true (or its sender is gone).
async fn stopped(stop: &mut watch::Receiver<bool>) {
    let _ = stop.wait_for(|s| *s).await;
}

/// Middleware: read the request's body (at most [`MAX_BODY_BYTES`]) within
/// `timeout`, else answer `408`.
async fn read_body(State(timeout): State<Duration>, req: Request, next: Next) -> Response {
    let (parts, body) = req.into_parts();
    match tokio::time::timeout(timeout, axum::body::to_bytes(body, MAX_BODY_BYTES)).await {
        Ok(Ok(bytes)) => {
            next.run(Request::from_parts(parts, Body::from(bytes)))
                .await
        }
        Ok(Err(e)) => error(
            StatusCode::PAYLOAD_TOO_LARGE,
            "bad_body",
            &format!("the request body could not be read: {e}"),
        ),
        Err(_) => error(
            StatusCode::REQUEST_TIMEOUT,
            "timeout",
            &format!("the request body did not arrive within {timeout:?}"),
        ),
    }
}

fn error(status: StatusCode, code: &str, message: &str) -> Response {
    let body = serde_json::json!({"error": code, "message": message});
    (status, axum::Json(body)).into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_limit_stays_below_the_descriptor_limit() {
        let t = DEFAULT_HEADER_TIMEOUT;
        assert_eq!(ConnectionLimits::new(None, t, None).max, 256);
        // systemd's default soft limit.
        assert_eq!(ConnectionLimits::new(None, t, Some(1024)).max, 256);
        assert_eq!(ConnectionLimits::new(Some(5000), t, Some(1024)).max, 960);
        assert_eq!(ConnectionLimits::new(Some(10), t, Some(40)).max, 1);
        assert!(descriptor_limit().is_none_or(|n| n > 0));
    }
}
