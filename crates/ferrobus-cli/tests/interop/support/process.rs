//! Child processes that cannot outlive their test.
//!
//! [`Proc`] owns a long-running child (a server, socat, the simulator): its output is read
//! line by line on two threads, kept for the failure message, and offered to
//! [`Proc::wait_for`], which is how a test learns that the child is ready. Dropping a
//! [`Proc`] kills the child (SIGKILL) and reaps it, on panic too. [`output_within`] runs a
//! short-lived command with a deadline, so that a hung peer fails the test instead of
//! hanging it.

use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread;
use std::time::{Duration, Instant};

/// Which output stream a line came from.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(crate) enum Stream {
    /// stdout.
    Out,
    /// stderr.
    Err,
}

/// A child process, killed on drop.
pub(crate) struct Proc {
    name: String,
    child: Child,
    lines: Receiver<(Stream, String)>,
    log: Arc<Mutex<String>>,
}

fn forward(stream: Stream, from: impl Read + Send + 'static, to: Sender<(Stream, String)>, log: Arc<Mutex<String>>) {
    thread::spawn(move || {
        for line in BufReader::new(from).lines() {
            let Ok(line) = line else { break };
            let tag = if stream == Stream::Out { "out" } else { "err" };
            let _ = writeln!(log.lock().unwrap_or_else(PoisonError::into_inner), "  [{tag}] {line}");
            if to.send((stream, line)).is_err() {
                // Nobody listens any more; keep draining so that the child never blocks.
            }
        }
    });
}

impl Proc {
    /// Starts `command` with stdin closed and stdout and stderr captured.
    ///
    /// # Panics
    /// If it cannot be started.
    pub(crate) fn spawn(name: &str, command: &mut Command) -> Proc {
        let mut child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("starting {name} ({command:?}): {e}"));
        let (tx, lines) = mpsc::channel();
        let log = Arc::new(Mutex::new(String::new()));
        if let Some(out) = child.stdout.take() {
            forward(Stream::Out, out, tx.clone(), Arc::clone(&log));
        }
        if let Some(err) = child.stderr.take() {
            forward(Stream::Err, err, tx, Arc::clone(&log));
        }
        Proc { name: name.to_string(), child, lines, log }
    }

    /// Waits for a line on `stream` for which `ready` holds, and returns it. Lines before it
    /// are skipped (they stay in the log).
    ///
    /// # Panics
    /// If the child closes its output (exits) first, or nothing matches `within`.
    pub(crate) fn wait_for(&self, stream: Stream, ready: impl Fn(&str) -> bool, within: Duration) -> String {
        let deadline = Instant::now() + within;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.lines.recv_timeout(left) {
                Ok((s, line)) if s == stream && ready(&line) => return line,
                Ok(_) => {}
                Err(RecvTimeoutError::Timeout) => {
                    panic!("{} was not ready within {within:?}; its output:\n{}", self.name, self.log())
                }
                Err(RecvTimeoutError::Disconnected) => {
                    panic!("{} exited before it was ready:\n{}", self.name, self.log())
                }
            }
        }
    }

    /// The child's process id (to send it a signal).
    pub(crate) fn id(&self) -> u32 {
        self.child.id()
    }

    /// Everything the child has printed so far.
    pub(crate) fn log(&self) -> String {
        self.log.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }

    /// Whether the child is still running.
    pub(crate) fn running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Stops the child with SIGTERM, so that it can clean up (socat removes its links), and
    /// waits for it; SIGKILL if it has not exited after 5 s.
    pub(crate) fn terminate(&mut self) {
        let _ = Command::new("kill").args(["-TERM", &self.child.id().to_string()]).status();
        let deadline = Instant::now() + Duration::from_secs(5);
        while self.running() && Instant::now() < deadline {
            thread::sleep(Duration::from_millis(5));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Runs `command` to completion, feeding it `stdin`, and returns its output; kills it and
/// panics if it takes longer than `limit`.
///
/// # Panics
/// If it cannot be started or does not finish in time.
pub(crate) fn output_within(command: &mut Command, stdin: &str, limit: Duration) -> Output {
    let mut child = command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("starting {command:?}: {e}"));
    let pid = child.id();
    let input = stdin.to_string();
    let mut pipe = child.stdin.take();
    thread::spawn(move || {
        if let Some(pipe) = pipe.as_mut() {
            let _ = pipe.write_all(input.as_bytes());
        }
        // Dropping the pipe closes stdin: the end of the script.
    });
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let _ = tx.send(child.wait_with_output());
    });
    if let Ok(output) = rx.recv_timeout(limit) {
        return output.unwrap_or_else(|e| panic!("waiting for {command:?}: {e}"));
    }
    let _ = Command::new("kill").args(["-KILL", &pid.to_string()]).status();
    panic!("{command:?} did not finish within {limit:?} (killed)");
}
