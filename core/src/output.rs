//! Where the command-line tools write: results to stdout through writes whose errors are
//! returned ([`say!`](crate::say), [`write_stdout`]), diagnostics to stderr through writes that
//! cannot fail ([`note!`](crate::note)). `println!` and `eprintln!` panic when their reader has
//! gone away (`qicp sweep … --json | head -1`, or `2>&1 | head -3`); with these a closed
//! stdout is an error the program can end on quietly, and a closed stderr stops no work.

/// A result that could not be written to stdout.
#[derive(Debug, thiserror::Error)]
#[error("cannot write to stdout")]
pub struct StdoutError(#[from] pub std::io::Error);

impl StdoutError {
    /// Whether stdout's reader closed it before the write: the reader has what it wanted.
    #[must_use]
    pub fn reader_went_away(&self) -> bool {
        self.0.kind() == std::io::ErrorKind::BrokenPipe
    }
}

/// Writes `text` to stdout as it is (no newline added).
///
/// # Errors
/// [`StdoutError`] when stdout cannot be written.
pub fn write_stdout(text: &str) -> Result<(), StdoutError> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    out.write_all(text.as_bytes())?;
    out.flush()?;
    Ok(())
}

/// `println!` that returns a [`StdoutError`] instead of panicking when stdout cannot be
/// written.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        ::std::writeln!(::std::io::stdout().lock(), $($arg)*).map_err($crate::output::StdoutError)
    }};
}

/// `eprintln!` that cannot panic: a diagnostic (progress, a warning, a note about the input)
/// goes to stderr while stderr is there and is dropped once its reader has gone away, so that
/// the work it describes goes on.
#[macro_export]
macro_rules! note {
    ($($arg:tt)*) => {{
        use ::std::io::Write as _;
        let _ = ::std::writeln!(::std::io::stderr(), $($arg)*);
    }};
}
