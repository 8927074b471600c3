//! Why a configuration was refused: one error type for every TOML file qicp reads (a
//! matcher's `[matcher]` table, a simulated drive, an experiment), each naming the dotted key
//! at fault.

use thiserror::Error;

/// A configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file cannot be read.
    #[error("reading {path}: {cause}")]
    Io {
        /// The file.
        path: String,
        /// Why (part of the message, not a separate `source()`: a printed chain of causes
        /// shows it once).
        cause: std::io::Error,
    },
    /// The TOML does not parse or does not fit the schema (unknown key, wrong type…); the
    /// message names the key and shows the offending line where the parser gives them.
    #[error("{0}")]
    Parse(String),
    /// A value is missing, contradictory or out of range.
    #[error("`{key}`: {why}")]
    Invalid {
        /// Dotted path of the key, e.g. `matcher.icp.max_dist_end` or `laser.beams`.
        key: String,
        /// What is wrong.
        why: String,
    },
    /// A section the chosen matcher does not use.
    #[error("`{key}` is not used by matcher kind `{kind}`")]
    Unused {
        /// Dotted path of the section.
        key: String,
        /// The chosen matcher's composed name.
        kind: String,
    },
    /// A table inside the file is wrong, e.g. an experiment's `[matchers.q-wsm]`.
    #[error("`{key}`: {inner}")]
    In {
        /// Dotted path of the table.
        key: String,
        /// What is wrong inside it (part of the message, as for `Io`).
        inner: Box<ConfigError>,
    },
}

impl ConfigError {
    /// A value refused: `key` is its dotted path.
    pub fn invalid(key: &str, why: impl Into<String>) -> Self {
        Self::Invalid {
            key: key.into(),
            why: why.into(),
        }
    }

    /// `self`, found inside the table at `key`.
    #[must_use]
    pub fn inside(self, key: impl Into<String>) -> Self {
        Self::In {
            key: key.into(),
            inner: Box::new(self),
        }
    }

    /// The dotted key at fault, where there is one (the innermost for a nested error).
    #[must_use]
    pub fn key(&self) -> Option<&str> {
        match self {
            Self::Invalid { key, .. } | Self::Unused { key, .. } => Some(key),
            Self::In { inner, .. } => inner.key(),
            Self::Io { .. } | Self::Parse(_) => None,
        }
    }
}
