//! One error type for the CLI: every library error becomes one clear line and an exit code.

use std::fmt;
use std::process::ExitCode;

/// The exit codes every subcommand shares (README, "Exit codes").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// 0: success.
    Ok = 0,
    /// 1: the input was read but has findings (validation errors, items rejected, tolerance not reached).
    Findings = 1,
    /// 2: usage error (bad options).
    Usage = 2,
    /// 3: input that cannot be read or parsed at all.
    Unreadable = 3,
    /// 4: internal failure (including failing to write an output).
    Internal = 4,
}

impl From<Exit> for ExitCode {
    fn from(e: Exit) -> ExitCode {
        ExitCode::from(e as u8)
    }
}

#[derive(Debug)]
pub struct CliError {
    pub exit: Exit,
    pub message: String,
}

impl CliError {
    pub fn new(exit: Exit, message: impl Into<String>) -> Self {
        CliError { exit, message: message.into() }
    }
    pub fn usage(m: impl Into<String>) -> Self {
        Self::new(Exit::Usage, m)
    }
    pub fn unreadable(m: impl Into<String>) -> Self {
        Self::new(Exit::Unreadable, m)
    }
    pub fn findings(m: impl Into<String>) -> Self {
        Self::new(Exit::Findings, m)
    }
    pub fn internal(m: impl Into<String>) -> Self {
        Self::new(Exit::Internal, m)
    }
    pub fn output(m: impl Into<String>) -> Self {
        Self::new(Exit::Internal, m)
    }
    pub fn io_out(e: std::io::Error) -> Self {
        Self::new(Exit::Internal, format!("write failed: {e}"))
    }
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for CliError {}

/// The result of a subcommand: which exit code to use when it did not fail outright.
pub type CmdResult = Result<Exit, CliError>;
