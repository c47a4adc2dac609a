//! `Input`: a path or stdin (`-`), read whole within the byte budget or memory-mapped.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use crate::error::CliError;
use input_limits::mapped::InputBytes;

/// Where an input comes from: a path or `-` for stdin.
#[derive(Debug, Clone)]
pub enum Input {
    Stdin,
    Path(PathBuf),
}

impl Input {
    pub fn from_arg(arg: &str) -> Input {
        if arg == "-" {
            Input::Stdin
        } else {
            Input::Path(PathBuf::from(arg))
        }
    }

    /// The name used in error messages (`<stdin>` or the path as given).
    pub fn display_name(&self) -> String {
        match self {
            Input::Stdin => "<stdin>".to_string(),
            Input::Path(p) => p.display().to_string(),
        }
    }

    /// The file path, if the input is a file (needed by libraries that open paths themselves, e.g. GDAL).
    pub fn path(&self) -> Option<&Path> {
        match self {
            Input::Stdin => None,
            Input::Path(p) => Some(p),
        }
    }

    /// Opens the input for buffered streaming reads.
    pub fn open(&self) -> Result<Box<dyn BufRead>, CliError> {
        match self {
            Input::Stdin => {
                let mut r = BufReader::with_capacity(1 << 16, io::stdin());
                if r.fill_buf().map_err(|e| CliError::unreadable(format!("<stdin>: {e}")))?.is_empty() {
                    return Err(no_input());
                }
                Ok(Box::new(r))
            }
            Input::Path(p) => {
                let f = File::open(p).map_err(|e| CliError::unreadable(format!("{}: {e}", p.display())))?;
                Ok(Box::new(BufReader::with_capacity(1 << 16, f)))
            }
        }
    }

    /// Reads the whole input into memory, within the byte budget
    /// (`input_limits::budget::ByteBudget`): a regular file is refused by its size before a byte
    /// is read, a pipe or device (`/dev/zero`, an endless stdin) once it has delivered more than
    /// the budget, with exit 3 naming the limit instead of the machine running out of memory.
    ///
    /// A CityJSON or CityJSONSeq input comes back as CityGML 2.0 text (issue 38; see
    /// `encoding::as_citygml`); [`Input::read_all_raw`] gives the bytes as they are.
    pub fn read_all(&self) -> Result<Vec<u8>, CliError> {
        super::encoding::as_citygml(&self.display_name(), self.read_all_raw()?)
    }

    /// The whole input as it is, within the byte budget.
    pub fn read_all_raw(&self) -> Result<Vec<u8>, CliError> {
        self.read_all_within(input_limits::budget::ByteBudget::current())
    }

    /// The whole input for a reader that streams through it once (the CityGML object stream):
    /// a regular file is memory-mapped, whatever its size, and the reader releases the pages
    /// behind it (`InputBytes::release_before`), so memory stays bounded by the largest object
    /// (docs/decisions.md#streaming-citygml); anything else is read whole within the byte budget.
    ///
    /// CityJSON comes back as CityGML 2.0 text: a CityJSONSeq file converted line by line into a
    /// mapped temporary file (bounded memory), a CityJSON document read whole and converted.
    pub fn map_or_read(&self) -> Result<InputBytes, CliError> {
        let mapped = self.map_or_read_raw()?;
        match super::encoding::Encoding::of_bytes(&mapped) {
            super::encoding::Encoding::CityGml => Ok(mapped),
            super::encoding::Encoding::CityJsonSeq if matches!(mapped, InputBytes::Mapped { .. }) => {
                let path = self.path().expect("a mapped input is a file");
                drop(mapped);
                super::encoding::map_seq_as_citygml(&self.display_name(), path)
            }
            _ => super::encoding::as_citygml(&self.display_name(), mapped.to_vec()).map(InputBytes::Read),
        }
    }

    /// [`Input::map_or_read`] without the CityJSON conversion: the bytes as they are.
    pub fn map_or_read_raw(&self) -> Result<InputBytes, CliError> {
        let unreadable = |e: io::Error| CliError::unreadable(format!("{}: {e}", self.display_name()));
        if let Some(p) = self.path() {
            let file = File::open(p).map_err(unreadable)?;
            if file.metadata().map_err(unreadable)?.is_file() {
                return InputBytes::map(&file).map_err(unreadable);
            }
        }
        self.read_all_raw().map(InputBytes::Read)
    }

    fn read_all_within(&self, budget: input_limits::budget::ByteBudget) -> Result<Vec<u8>, CliError> {
        let too_big = || {
            CliError::unreadable(format!(
                "{}: too large to read whole (more than {})",
                self.display_name(),
                budget.describe()
            ))
        };
        let known_len = self.path().and_then(|p| std::fs::metadata(p).ok()).filter(|m| m.is_file()).map(|m| m.len());
        if known_len.is_some_and(|len| !budget.allows(len)) {
            return Err(too_big());
        }
        let mut buf = Vec::with_capacity(known_len.unwrap_or(0) as usize);
        self.open()?
            .take(budget.max_bytes.saturating_add(1))
            .read_to_end(&mut buf)
            .map_err(|e| CliError::unreadable(format!("{}: {e}", self.display_name())))?;
        if !budget.allows(buf.len() as u64) {
            return Err(too_big());
        }
        if buf.is_empty() && matches!(self, Input::Stdin) {
            return Err(no_input());
        }
        Ok(buf)
    }
}

/// An empty stdin: in a pipe (`citygml2popa3d IN | adjust -`) the stage before failed or wrote
/// nothing, and saying so beats the reader's "1:1: not a popa3d document".
fn no_input() -> CliError {
    CliError::unreadable("<stdin>: no input (the previous stage wrote nothing)")
}
