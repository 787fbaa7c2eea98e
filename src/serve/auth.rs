//! Bearer-token authentication for the control API.
//!
//! Off the loopback interface the daemon requires a token, read from a
//! file; every request must then carry `Authorization: Bearer <token>`.
//! The comparison takes the same time wherever the tokens differ
//! (`subtle`); a wrong or missing token gets 401 and no other answer, also
//! on paths that do not exist.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use axum::extract::{Request, State};
use axum::http::{header, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use subtle::ConstantTimeEq;

/// Shortest token accepted, characters.
pub const MIN_TOKEN_LEN: usize = 16;

/// Why a token file is refused.
#[derive(Debug, thiserror::Error)]
pub enum TokenError {
    /// The file could not be read.
    #[error("{}: cannot read the token file: {source}", path.display())]
    Read {
        /// The token file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The token is shorter than [`MIN_TOKEN_LEN`].
    #[error("{}: the token is {len} characters; at least {MIN_TOKEN_LEN} are needed", path.display())]
    TooShort {
        /// The token file.
        path: PathBuf,
        /// The token's length, characters.
        len: usize,
    },
    /// The token holds a character other than printable ASCII.
    #[error("{}: the token may hold printable ASCII only (no spaces)", path.display())]
    NotPrintable {
        /// The token file.
        path: PathBuf,
    },
}

/// The API token.
#[derive(Clone)]
pub struct Token(Arc<Vec<u8>>);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(…)")
    }
}

impl Token {
    /// Read a token file: its content without surrounding whitespace, at
    /// least [`MIN_TOKEN_LEN`] characters, printable ASCII only.
    pub fn load(path: &Path) -> Result<Token, TokenError> {
        let text = std::fs::read_to_string(path).map_err(|source| TokenError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let token = text.trim();
        if token.len() < MIN_TOKEN_LEN {
            return Err(TokenError::TooShort {
                path: path.to_path_buf(),
                len: token.len(),
            });
        }
        if !token.bytes().all(|b| b.is_ascii_graphic()) {
            return Err(TokenError::NotPrintable {
                path: path.to_path_buf(),
            });
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            if let Ok(m) = std::fs::metadata(path) {
                if m.permissions().mode() & 0o004 != 0 {
                    tracing::warn!(
                        "{}: the token file is readable by every user; chmod o-r it",
                        path.display()
                    );
                }
            }
        }
        Ok(Token(Arc::new(token.as_bytes().to_vec())))
    }

    /// A token from text (tests, the client).
    pub fn from_text(text: &str) -> Token {
        Token(Arc::new(text.trim().as_bytes().to_vec()))
    }

    /// The token text (for the client's header).
    pub fn as_str(&self) -> &str {
        std::str::from_utf8(&self.0).unwrap_or("")
    }

    /// True when `header` is `Bearer <this token>`.
    pub fn accepts(&self, header: Option<&[u8]>) -> bool {
        let Some(given) = header.and_then(|h| h.strip_prefix(b"Bearer ")) else {
            return false;
        };
        // Length is not secret; the content is compared in constant time.
        given.len() == self.0.len() && bool::from(given.ct_eq(&self.0))
    }
}

/// Middleware: 401 unless the request carries the token.
pub async fn require_token(State(token): State<Token>, request: Request, next: Next) -> Response {
    let given = request
        .headers()
        .get(header::AUTHORIZATION)
        .map(|v| v.as_bytes());
    if token.accepts(given) {
        next.run(request).await
    } else {
        (
            StatusCode::UNAUTHORIZED,
            [(header::WWW_AUTHENTICATE, "Bearer")],
            axum::Json(serde_json::json!({
                "error": "unauthorized",
                "message": "this endpoint needs `Authorization: Bearer <token>`"
            })),
        )
            .into_response()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accepts_only_the_exact_bearer_token() {
        let t = Token::from_text("0123456789abcdef0123\n");
        assert!(t.accepts(Some(b"Bearer 0123456789abcdef0123")));
        assert!(!t.accepts(Some(b"Bearer 0123456789abcdef012")));
        assert!(!t.accepts(Some(b"Bearer 0123456789abcdef01234")));
        assert!(!t.accepts(Some(b"Bearer 0123456789abcdef0124")));
        assert!(!t.accepts(Some(b"bearer 0123456789abcdef0123")));
        assert!(!t.accepts(Some(b"0123456789abcdef0123")));
        assert!(!t.accepts(None));
    }

    #[test]
    fn token_files_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("token");
        std::fs::write(&p, "short\n").unwrap();
        let e = Token::load(&p).unwrap_err();
        assert!(matches!(e, TokenError::TooShort { len: 5, .. }), "{e:?}");
        assert_eq!(
            e.to_string(),
            format!(
                "{}: the token is 5 characters; at least 16 are needed",
                p.display()
            )
        );
        std::fs::write(&p, "has a space in the middle\n").unwrap();
        let e = Token::load(&p).unwrap_err();
        assert!(matches!(e, TokenError::NotPrintable { .. }), "{e:?}");
        assert!(e.to_string().contains("printable"));
        std::fs::write(&p, "  0123456789abcdef0123  \n").unwrap();
        assert_eq!(Token::load(&p).unwrap().as_str(), "0123456789abcdef0123");
        let e = Token::load(&dir.path().join("none")).unwrap_err();
        assert!(matches!(e, TokenError::Read { .. }), "{e:?}");
        assert!(e.to_string().contains("cannot read"), "{e}");
    }
}
