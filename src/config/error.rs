//! What is wrong with a configuration file: the error type every
//! machine's configuration returns, naming the file, the line and the key,
//! and the constructors the parsers share.

use thiserror::Error;

use super::key_line;
use crate::bounds;
use crate::excerpt::cut;

/// A configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Read {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// TOML syntax error, wrong type or unknown key.
    #[error("{path}:{line}: {message} (in `{text}`)")]
    Parse {
        /// The file.
        path: String,
        /// 1-based line of the offending text.
        line: usize,
        /// The offending line, trimmed.
        text: String,
        /// What the parser said, on one line.
        message: String,
    },
    /// A value parsed but is not usable.
    #[error("{path}{}: {key}: {reason}", at_line(*.line))]
    Invalid {
        /// The file.
        path: String,
        /// 1-based line of the key (or of the deepest part of its path the
        /// file has), where known.
        line: Option<usize>,
        /// Dotted key path.
        key: String,
        /// Why.
        reason: String,
    },
}

/// `checked` with its error as an invalid value of `key` in `source`.
pub(crate) fn bounded<T>(
    source: &str,
    key: &str,
    checked: Result<T, bounds::BoundsError>,
) -> Result<T, ConfigError> {
    checked.map_err(|reason| invalid(source, key, reason.to_string()))
}

/// An invalid value of `key` in `source` (its line filled in later by
/// [`ConfigError::located`]).
pub(crate) fn invalid(source: &str, key: &str, reason: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        path: source.to_string(),
        line: None,
        key: key.to_string(),
        reason: reason.into(),
    }
}

/// A TOML syntax, type or unknown-key error in `text` (from `source`),
/// with its line.
pub(crate) fn syntax_error(source: &str, text: &str, e: &toml::de::Error) -> ConfigError {
    let start = e.span().map(|s| s.start).unwrap_or(0).min(text.len());
    let line = text[..start].matches('\n').count() + 1;
    ConfigError::Parse {
        path: source.to_string(),
        line,
        text: cut(text.lines().nth(line - 1).unwrap_or("").trim()),
        message: e.message().replace('\n', " ").trim().to_string(),
    }
}

/// `:line` when the line is known.
fn at_line(line: Option<usize>) -> String {
    line.map(|l| format!(":{l}")).unwrap_or_default()
}

impl ConfigError {
    /// The error with the line of its key in `text` (when given) filled in.
    pub(crate) fn located(self, text: Option<&str>) -> ConfigError {
        match self {
            ConfigError::Invalid {
                path,
                line: None,
                key,
                reason,
            } => ConfigError::Invalid {
                line: text.and_then(|t| key_line(t, &key)),
                path,
                key,
                reason,
            },
            other => other,
        }
    }
}
