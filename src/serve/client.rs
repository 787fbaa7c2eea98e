//! A small HTTP/1.1 client for the control API, over TCP or a Unix
//! socket (hyper's connection API; no TLS: the API is meant for the
//! loopback interface, a Unix socket, or a tunnel).

use std::path::{Path, PathBuf};

use axum::body::Bytes;
use http_body_util::{BodyExt, Full};
use hyper::body::Incoming;
use hyper::client::conn::http1;
use hyper::{Method, Request, Response};
use hyper_util::rt::TokioIo;
use thiserror::Error;

/// Where the API is.
#[derive(Debug, Clone, PartialEq)]
pub enum Endpoint {
    /// `http://HOST:PORT`.
    Tcp(String),
    /// `unix:/path/to/socket`.
    Unix(PathBuf),
}

impl Endpoint {
    /// Parse `http://HOST:PORT` (no path) or `unix:PATH`.
    pub fn parse(url: &str) -> Result<Endpoint, EndpointError> {
        if let Some(path) = url.strip_prefix("unix:") {
            if path.is_empty() {
                return Err(EndpointError::NoSocketPath { url: url.into() });
            }
            return Ok(Endpoint::Unix(PathBuf::from(path)));
        }
        let Some(authority) = url.strip_prefix("http://") else {
            return Err(EndpointError::Scheme { url: url.into() });
        };
        let authority = authority.trim_end_matches('/');
        if authority.is_empty() || authority.contains('/') {
            return Err(EndpointError::Authority { url: url.into() });
        }
        Ok(Endpoint::Tcp(authority.to_string()))
    }
}

/// Why an API address is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum EndpointError {
    /// `unix:` with no path after it.
    #[error("{url}: no socket path after `unix:`")]
    NoSocketPath {
        /// The address as given.
        url: String,
    },
    /// Neither `http://` nor `unix:`.
    #[error("{url}: give http://HOST:PORT or unix:PATH (https is not supported: use a tunnel)")]
    Scheme {
        /// The address as given.
        url: String,
    },
    /// `http://` with no host, or with a path.
    #[error("{url}: give http://HOST:PORT with no path")]
    Authority {
        /// The address as given.
        url: String,
    },
}

/// A failed exchange.
#[derive(Debug, Error)]
pub enum ClientError {
    /// No connection, or the connection broke.
    #[error("cannot reach the daemon at {endpoint}: {reason}")]
    Connect {
        /// Where.
        endpoint: String,
        /// Why.
        reason: String,
    },
    /// A local file could not be written.
    #[error("{path}: {reason}")]
    File {
        /// The file.
        path: String,
        /// Why.
        reason: String,
    },
}

/// An answer.
#[derive(Debug, Clone)]
pub struct Reply {
    /// HTTP status code.
    pub status: u16,
    /// The `Content-Type` header, when there was one.
    pub content_type: Option<String>,
    /// The body.
    pub body: Bytes,
}

impl Reply {
    /// The body as JSON (`null` when it is not JSON).
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body).unwrap_or(serde_json::Value::Null)
    }

    /// True for 2xx.
    pub fn ok(&self) -> bool {
        (200..300).contains(&self.status)
    }
}

/// The API client.
#[derive(Debug, Clone)]
pub struct Client {
    endpoint: Endpoint,
    token: Option<String>,
}

type Sender = http1::SendRequest<Full<Bytes>>;

impl Client {
    /// A client for `endpoint`, sending `token` when given.
    pub fn new(endpoint: Endpoint, token: Option<String>) -> Client {
        Client { endpoint, token }
    }

    fn describe(&self) -> String {
        match &self.endpoint {
            Endpoint::Tcp(a) => format!("http://{a}"),
            Endpoint::Unix(p) => format!("unix:{}", p.display()),
        }
    }

    fn connect_err(&self, reason: impl std::fmt::Display) -> ClientError {
        ClientError::Connect {
            endpoint: self.describe(),
            reason: reason.to_string(),
        }
    }

    async fn connect(&self) -> Result<Sender, ClientError> {
        match &self.endpoint {
            Endpoint::Tcp(authority) => {
                let stream = tokio::net::TcpStream::connect(authority)
                    .await
                    .map_err(|e| self.connect_err(e))?;
                self.handshake(stream).await
            }
            Endpoint::Unix(path) => {
                let stream = tokio::net::UnixStream::connect(path)
                    .await
                    .map_err(|e| self.connect_err(e))?;
                self.handshake(stream).await
            }
        }
    }

    /// The HTTP/1.1 handshake on a connected `stream`; the connection
    /// task is spawned and ends with the connection.
    async fn handshake<S>(&self, stream: S) -> Result<Sender, ClientError>
    where
        S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
    {
        let (s, conn) = http1::handshake(TokioIo::new(stream))
            .await
            .map_err(|e| self.connect_err(e))?;
        tokio::spawn(conn);
        Ok(s)
    }

    fn build(
        &self,
        method: Method,
        path: &str,
        body: Option<&serde_json::Value>,
    ) -> Request<Full<Bytes>> {
        let host = match &self.endpoint {
            Endpoint::Tcp(a) => a.as_str(),
            Endpoint::Unix(_) => "localhost",
        };
        let mut b = Request::builder()
            .method(method)
            .uri(path)
            .header(hyper::header::HOST, host);
        if let Some(t) = &self.token {
            b = b.header(hyper::header::AUTHORIZATION, format!("Bearer {t}"));
        }
        let body = match body {
            Some(v) => {
                b = b.header(hyper::header::CONTENT_TYPE, "application/json");
                Full::new(Bytes::from(v.to_string()))
            }
            None => Full::new(Bytes::new()),
        };
        b.body(body).expect("a valid request")
    }

    /// Send a request and read the whole answer.
    pub async fn request(
        &self,
        method: Method,
        path: &str,
        body: Option<&serde_json::Value>,
    ) -> Result<Reply, ClientError> {
        let response = self.send(method, path, body).await?;
        self.read_reply(response).await
    }

    /// Connect and send a request; the answer's head, its body unread.
    async fn send(
        &self,
        method: Method,
        path: &str,
        body: Option<&serde_json::Value>,
    ) -> Result<Response<Incoming>, ClientError> {
        let mut sender = self.connect().await?;
        sender
            .send_request(self.build(method, path, body))
            .await
            .map_err(|e| self.connect_err(e))
    }

    /// Read the whole answer.
    async fn read_reply(&self, response: Response<Incoming>) -> Result<Reply, ClientError> {
        let status = response.status().as_u16();
        let content_type = response
            .headers()
            .get(hyper::header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .map(str::to_string);
        let body = response
            .into_body()
            .collect()
            .await
            .map_err(|e| self.connect_err(e))?
            .to_bytes();
        Ok(Reply {
            status,
            content_type,
            body,
        })
    }

    /// GET `path`.
    pub async fn get(&self, path: &str) -> Result<Reply, ClientError> {
        self.request(Method::GET, path, None).await
    }

    /// POST `path` with an optional JSON body.
    pub async fn post(
        &self,
        path: &str,
        body: Option<&serde_json::Value>,
    ) -> Result<Reply, ClientError> {
        self.request(Method::POST, path, body).await
    }

    /// Follow server-sent events at `path`: `on_event(name, data)` for
    /// each event until it returns false or the stream ends. Returns the
    /// status when the answer is not 2xx (with its body), else `None`.
    pub async fn events(
        &self,
        path: &str,
        mut on_event: impl FnMut(&str, &str) -> bool,
    ) -> Result<Option<Reply>, ClientError> {
        let response = self.send(Method::GET, path, None).await?;
        if !response.status().is_success() {
            return self.read_reply(response).await.map(Some);
        }
        let mut body = response.into_body();
        let mut parser = SseParser::default();
        while let Some(frame) = body.frame().await {
            let frame = frame.map_err(|e| self.connect_err(e))?;
            if let Some(data) = frame.data_ref() {
                for (name, data) in parser.push(data) {
                    if !on_event(&name, &data) {
                        return Ok(None);
                    }
                }
            }
        }
        Ok(None)
    }

    /// Download `path` into `dest` (written to `dest.part`, then renamed).
    /// Returns the status and, on success, the byte count.
    pub async fn download(&self, path: &str, dest: &Path) -> Result<(u16, u64), ClientError> {
        use tokio::io::AsyncWriteExt;
        let response = self.send(Method::GET, path, None).await?;
        let status = response.status().as_u16();
        if !(200..300).contains(&status) {
            return Ok((status, 0));
        }
        let file_err = |e: std::io::Error| ClientError::File {
            path: dest.display().to_string(),
            reason: e.to_string(),
        };
        let part = dest.with_extension("part");
        let mut file = tokio::fs::File::create(&part).await.map_err(file_err)?;
        let mut body = response.into_body();
        let mut n = 0u64;
        while let Some(frame) = body.frame().await {
            let frame = frame.map_err(|e| self.connect_err(e))?;
            if let Some(data) = frame.data_ref() {
                file.write_all(data).await.map_err(file_err)?;
                n += data.len() as u64;
            }
        }
        file.flush().await.map_err(file_err)?;
        drop(file);
        tokio::fs::rename(&part, dest).await.map_err(file_err)?;
        Ok((status, n))
    }
}

/// Splits a server-sent event stream into `(event name, data)` pairs.
///
/// Bytes are kept until an event's blank line has arrived, and only a
/// whole event is decoded: a multi-byte character split across network
/// chunks (`→`, `°`, `Ω`) comes out whole. Lines may end in `\n` or
/// `\r\n`.
#[derive(Debug, Default)]
pub struct SseParser {
    buffer: Vec<u8>,
    /// Where the next line starts in `buffer`.
    line_start: usize,
    /// Where the search for the next line end resumes.
    scanned: usize,
}

impl SseParser {
    /// Feed bytes; the events completed by them.
    pub fn push(&mut self, bytes: &[u8]) -> Vec<(String, String)> {
        self.buffer.extend_from_slice(bytes);
        let mut out = Vec::new();
        while let Some(nl) = self.buffer[self.scanned..].iter().position(|&b| b == b'\n') {
            let end = self.scanned + nl;
            self.scanned = end + 1;
            let line = &self.buffer[self.line_start..end];
            let blank = line.is_empty() || line == b"\r";
            self.line_start = end + 1;
            if !blank {
                continue;
            }
            let block: Vec<u8> = self.buffer.drain(..=end).collect();
            self.line_start = 0;
            self.scanned = 0;
            if let Some(event) = parse_block(&String::from_utf8_lossy(&block)) {
                out.push(event);
            }
        }
        out
    }
}

/// One event's lines → `(name, data)`; `None` for a block without data
/// (a comment, e.g. a keep-alive).
fn parse_block(block: &str) -> Option<(String, String)> {
    let mut name = "message".to_string();
    let mut data: Vec<&str> = Vec::new();
    for line in block.lines() {
        if let Some(v) = line.strip_prefix("event:") {
            name = v.trim_start().to_string();
        } else if let Some(v) = line.strip_prefix("data:") {
            data.push(v.strip_prefix(' ').unwrap_or(v));
        }
    }
    (!data.is_empty()).then(|| (name, data.join("\n")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn endpoints_parse() {
        assert_eq!(
            Endpoint::parse("http://127.0.0.1:7461/").unwrap(),
            Endpoint::Tcp("127.0.0.1:7461".into())
        );
        assert_eq!(
            Endpoint::parse("unix:/run/motorbench/api.sock").unwrap(),
            Endpoint::Unix("/run/motorbench/api.sock".into())
        );
        assert!(Endpoint::parse("https://host:1")
            .unwrap_err()
            .to_string()
            .contains("tunnel"));
        assert!(matches!(
            Endpoint::parse("https://host:1"),
            Err(EndpointError::Scheme { .. })
        ));
        assert!(Endpoint::parse("http://host:1/v1").is_err());
        assert!(Endpoint::parse("unix:").is_err());
    }

    #[test]
    fn sse_events_split_across_chunks() {
        let mut p = SseParser::default();
        assert!(p.push(b"event: progress\ndata: {\"t_s\"").is_empty());
        let got = p.push(b":1}\n\n:keep-alive\n\nevent: done\r\ndata: a\r\ndata: b\r\n\r\n");
        assert_eq!(
            got,
            [
                ("progress".to_string(), "{\"t_s\":1}".to_string()),
                ("done".to_string(), "a\nb".to_string())
            ]
        );
    }

    #[test]
    fn a_character_split_across_chunks_comes_out_whole() {
        let event = "event: progress\ndata: {\"label\":\"0 V → 60 V, 40 °C, 30 Ω\"}\n\n";
        let bytes = event.as_bytes();
        let want = [(
            "progress".to_string(),
            "{\"label\":\"0 V → 60 V, 40 °C, 30 Ω\"}".to_string(),
        )];
        // Every split point, including those inside `→` (3 bytes), `°` and `Ω` (2 each).
        for cut in 1..bytes.len() {
            let mut p = SseParser::default();
            let mut got = p.push(&bytes[..cut]);
            got.extend(p.push(&bytes[cut..]));
            assert_eq!(got, want, "split at byte {cut}");
        }
        // One byte at a time, with CRLF line ends.
        let crlf = event.replace('\n', "\r\n");
        let mut p = SseParser::default();
        let got: Vec<_> = crlf.as_bytes().iter().flat_map(|b| p.push(&[*b])).collect();
        assert_eq!(got, want);
    }
}
