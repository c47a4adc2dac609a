//! The one error type of point reading: every message names the input and, for text, the line
//! (`name:line: message`), so both dialects and LAS read the same way to a user.

#[derive(Debug, thiserror::Error)]
pub enum PointsError {
    /// A line of an XYZ/CSV file that does not hold a point of the dialect (line 0: the text
    /// as a whole, or a LAS input read in the LoopStructural dialect).
    #[error("{name}:{line}: {message}")]
    Line { name: String, line: usize, message: String },
    /// An I/O failure while reading.
    #[error("{name}: {message}")]
    Io { name: String, message: String },
    /// LAS/LAZ header or point decoding failure.
    #[error("{name}: {message}")]
    Las { name: String, message: String },
    /// The file held no usable point.
    #[error("{name}: {message}")]
    Empty { name: String, message: String },
    /// More points than the caller's point budget, or a LAS/LAZ header claiming more than the
    /// file holds (checked before the `las` crate allocates by it).
    #[error("{name}: {message}")]
    TooLarge { name: String, message: String },
}

impl PointsError {
    /// An error at a 1-based `line` of the text `name`.
    pub fn line(name: &str, line: usize, message: impl Into<String>) -> PointsError {
        PointsError::Line { name: name.into(), line, message: message.into() }
    }
}
