//! stderr, with every write checked: notes, reports and the log never panic on a full or
//! broken stderr (std's `eprintln!` does, exit 101), and the first failure is kept so that
//! the process ends with the output error's code.
//!
//! The crate's `eprintln!` and `eprint!` (defined in `main.rs`, before every module, so they
//! shadow std's everywhere in the crate) write through [`print`]; the log writes through
//! [`Log`]. A write that fails is dropped, and [`failure`] then holds why. `main` turns a
//! command that succeeded into exit 6 (141 for a closed pipe, as on stdout); a command that
//! failed keeps its own exit code, which says more than that its report could not be shown.
//!
//! A closed stderr (`2>&-`) is, for a Rust program, /dev/null: the standard library opens
//! /dev/null in its place at start, so that no file or socket takes descriptor 2 and gets the
//! messages meant for stderr. Writes to it succeed and are lost, as with `2>/dev/null`.

use std::fmt;
use std::io::{self, Write};
use std::sync::Mutex;

/// The first failed write to stderr, if one failed.
static FAILED: Mutex<Option<io::Error>> = Mutex::new(None);

/// Writes `args` to stderr and flushes it; a failure is kept for [`failure`].
pub(crate) fn print(args: fmt::Arguments<'_>) {
    let mut err = io::stderr().lock();
    if let Err(error) = err.write_fmt(args).and_then(|()| err.flush()) {
        record(error);
    }
}

/// Why a write to stderr failed, the first time one did.
pub(crate) fn failure() -> Option<io::Error> {
    let mut failed = FAILED.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    failed.take()
}

fn record(error: io::Error) {
    let mut failed = FAILED.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    failed.get_or_insert(error);
}

/// The log's writer: stderr, its failures kept like those of [`print`].
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Log;

impl Write for Log {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        io::stderr().write_all(buf).map_err(|error| {
            let kind = error.kind();
            record(error);
            io::Error::from(kind)
        })?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        io::stderr().flush().inspect_err(|error| record(io::Error::from(error.kind())))
    }
}

impl<'a> tracing_subscriber::fmt::MakeWriter<'a> for Log {
    type Writer = Log;

    fn make_writer(&'a self) -> Log {
        Log
    }
}
