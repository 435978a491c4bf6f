//! Serial lines without hardware: socat pty pairs, a per-test directory for their links, and
//! a raw port for sending exact RTU frames and timing the replies.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use super::process::{Proc, Stream};

/// A directory of its own for one test, removed on drop.
pub(crate) struct TempDir(PathBuf);

impl TempDir {
    /// A fresh, empty directory.
    ///
    /// # Panics
    /// If it cannot be made.
    pub(crate) fn new() -> TempDir {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("ferrobus-interop-{}-{n}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path).unwrap_or_else(|e| panic!("making {}: {e}", path.display()));
        TempDir(path)
    }

    /// Its path.
    pub(crate) fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Two ptys joined by socat: what one end writes, the other reads. Baud and parity are
/// stored but not applied, and bytes arrive at once.
pub(crate) struct SocatPair {
    proc: Option<Proc>,
    /// One end (a symlink to its pty).
    pub(crate) a: PathBuf,
    /// The other end.
    pub(crate) b: PathBuf,
}

impl SocatPair {
    /// `socat -d -d pty,raw,echo=0,link=DIR/a pty,raw,echo=0,link=DIR/b`, once both links exist.
    pub(crate) fn start(dir: &Path) -> SocatPair {
        let mut pair = SocatPair { proc: None, a: dir.join("a"), b: dir.join("b") };
        pair.restart();
        pair
    }

    /// Starts socat again with the same link names (after [`SocatPair::stop`]).
    ///
    /// # Panics
    /// If socat does not come up within 10 s.
    pub(crate) fn restart(&mut self) {
        let end = |link: &Path| format!("pty,raw,echo=0,link={}", link.display());
        let proc = Proc::spawn("socat", Command::new("socat").args(["-d", "-d", &end(&self.a), &end(&self.b)]));
        // socat makes both ptys and their links before it starts moving data.
        proc.wait_for(Stream::Err, |l| l.contains("starting data transfer loop"), Duration::from_secs(10));
        // Looked for a thousand times, 2 ms apart.
        let appeared = (0..1000).any(|_| {
            let both = self.a.exists() && self.b.exists();
            if !both {
                std::thread::sleep(Duration::from_millis(2));
            }
            both
        });
        assert!(appeared, "socat links {} and {} did not appear", self.a.display(), self.b.display());
        self.proc = Some(proc);
    }

    /// Stops socat: both ptys vanish and their links are removed.
    pub(crate) fn stop(&mut self) {
        if let Some(mut proc) = self.proc.take() {
            proc.terminate();
        }
    }
}

/// CRC-16/MODBUS of `bytes`, in wire order (low byte first).
pub(crate) fn crc16(bytes: &[u8]) -> [u8; 2] {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
        }
    }
    crc.to_le_bytes()
}

/// `bytes` with their CRC appended: an RTU frame.
pub(crate) fn with_crc(bytes: &[u8]) -> Vec<u8> {
    let mut frame = bytes.to_vec();
    frame.extend_from_slice(&crc16(bytes));
    frame
}

/// Hex bytes as the manuals print them: `"01 10 01 12"`.
pub(crate) fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace().map(|b| u8::from_str_radix(b, 16).unwrap_or_else(|e| panic!("{b:?}: {e}"))).collect()
}

/// Bytes as `01 10 01 12`, for messages.
pub(crate) fn show(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
}

/// A tty opened raw, written and read directly: a master that is not ferrobus.
pub(crate) struct RawPort(serial2::SerialPort);

impl RawPort {
    /// Opens `path` raw at `baud`, 8N1 (a pty ignores the format).
    ///
    /// # Panics
    /// If it cannot be opened.
    pub(crate) fn open(path: &Path, baud: u32) -> RawPort {
        let mut port =
            serial2::SerialPort::open(path, baud).unwrap_or_else(|e| panic!("opening {}: {e}", path.display()));
        port.set_read_timeout(Duration::from_secs(1)).expect("a read timeout");
        RawPort(port)
    }

    /// Writes `frame` whole and returns the instant just before the write: the frame cannot
    /// have reached the other end earlier, even if this thread is preempted after writing.
    pub(crate) fn send(&self, frame: &[u8]) -> Instant {
        let start = Instant::now();
        self.0.write_all(frame).expect("writing a frame");
        start
    }

    /// Reads `n` bytes, or what came before the 1 s read timeout; the instant the first byte
    /// was read is returned too.
    pub(crate) fn receive(&self, n: usize) -> (Vec<u8>, Option<Instant>) {
        let mut reply = vec![0u8; n];
        let mut got = 0;
        let mut first = None;
        while got < n {
            match self.0.read(&mut reply[got..]) {
                Ok(0) | Err(_) => break,
                Ok(k) => {
                    first.get_or_insert_with(Instant::now);
                    got += k;
                }
            }
        }
        reply.truncate(got);
        (reply, first)
    }

    /// Sends `frame` and reads a reply of `reply_len` bytes.
    pub(crate) fn transact(&self, frame: &[u8], reply_len: usize) -> Vec<u8> {
        self.send(frame);
        self.receive(reply_len).0
    }
}
