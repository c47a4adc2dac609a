//! Typed errors: every one names where it happened (the CityJSON object id, the CityJSONSeq
//! line) so the CLI prints one line a user can act on.

use thiserror::Error;

/// What went wrong reading or writing CityJSON.
#[derive(Debug, Error)]
pub enum CityJsonError {
    /// Not JSON at all (serde_json's message carries line and column).
    #[error("{line}:{column}: not valid JSON: {message}")]
    Json { line: usize, column: usize, message: String },
    /// JSON, but not CityJSON as the specification has it (a missing member, an index past
    /// the vertex list, ...). `object` is the CityJSON object id, `line` the CityJSONSeq line.
    #[error("{}{}{message}", line.map(|l| format!("{l}: ")).unwrap_or_default(), object.as_ref().map(|o| format!("object {o}: ")).unwrap_or_default())]
    Structure { line: Option<usize>, object: Option<String>, message: String },
    /// The CityGML input cannot be read (its reader's located error).
    #[error("{0}")]
    CityGml(#[from] citygml_io::ReadError),
    /// Reading or writing bytes failed.
    #[error("{0}")]
    Io(#[from] std::io::Error),
}

impl CityJsonError {
    pub(crate) fn json(e: &serde_json::Error, line_offset: usize) -> CityJsonError {
        CityJsonError::Json {
            line: e.line() + line_offset,
            column: e.column(),
            message: strip_position(&e.to_string()),
        }
    }

    pub(crate) fn structure(object: Option<&str>, message: impl Into<String>) -> CityJsonError {
        CityJsonError::Structure { line: None, object: object.map(str::to_string), message: message.into() }
    }

    /// The same error, located on CityJSONSeq line `line` (1-based).
    pub(crate) fn on_line(self, line: usize) -> CityJsonError {
        match self {
            CityJsonError::Structure { object, message, .. } => {
                CityJsonError::Structure { line: Some(line), object, message }
            }
            CityJsonError::Json { column, message, .. } => CityJsonError::Json { line, column, message },
            other => other,
        }
    }
}

/// serde_json appends " at line L column C"; the error prints its own position first.
fn strip_position(s: &str) -> String {
    match s.rfind(" at line ") {
        Some(at) => s[..at].to_string(),
        None => s.to_string(),
    }
}
