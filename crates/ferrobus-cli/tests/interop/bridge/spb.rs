//! The Sparkplug B tools nobody here wrote, as the bridge's tests use them: the fixtures of
//! tests/peers/sparkplug/ run in pysparkplug's venv (`target/peers/sparkplug-venv`, made by
//! `.ci/setup-peers.sh`), and Google's `protoc --decode_raw`.
//!
//! - [`Recorder`]: `record.py`, every message the broker delivers, one JSON line each, in a
//!   file kept after the test (`target/interop/bridge/<test>/recording.jsonl`) so that a failure
//!   can point at it;
//! - [`verify`]: `verify.py` on a recording, its JSON summary and errors;
//! - [`publish`]: `publish.py`, a DCMD, an NCMD Rebirth, a plain message, or a small edge
//!   session that follows (or breaks) the rules;
//! - [`decode_raw`]: `protoc --decode_raw` on one payload.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::thread;
use std::time::{Duration, Instant};

use serde_json::Value;

use crate::support::env::{self, Turn};
use crate::support::mosquitto::{self, Broker};
use crate::support::process::{Proc, Stream, output_within};

/// The venv's interpreter.
fn python() -> PathBuf {
    env::root().join("target/peers/sparkplug-venv/bin/python")
}

/// A fixture script of tests/peers/sparkplug/.
fn script(name: &str) -> PathBuf {
    env::root().join("tests/peers/sparkplug").join(name)
}

fn pysparkplug_importable() -> bool {
    Command::new(python())
        .args(["-c", "import pysparkplug, paho.mqtt.client"])
        .output()
        .is_ok_and(|o| o.status.success())
}

fn protoc_present() -> bool {
    Command::new("protoc").arg("--version").output().is_ok_and(|o| o.status.success())
}

/// The test's turn when mosquitto, pysparkplug's venv and protoc are all there; `None`
/// (after a `SKIPPED` line) when one is missing outside CI.
///
/// # Panics
/// Under `CI=true`, when one is missing.
pub(crate) fn require() -> Option<Turn> {
    let venv = env::require_tool(
        pysparkplug_importable(),
        &format!("pysparkplug 0.6.1 in {}", python().display()),
        ".ci/setup-peers.sh (a venv with pysparkplug==0.6.1)",
    );
    let protoc = venv && env::require_tool(protoc_present(), "protoc", "apt install protobuf-compiler");
    if protoc { mosquitto::require() } else { None }
}

/// `target/interop/bridge/<name>/`, emptied: where a test keeps what a failure message points at.
pub(crate) fn evidence_dir(name: &str) -> PathBuf {
    let dir = env::root().join("target/interop/bridge").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| panic!("making {}: {e}", dir.display()));
    dir
}

/// One recorded message.
#[derive(Clone, Debug)]
pub(crate) struct Message {
    /// Its topic.
    pub(crate) topic: String,
    /// The QoS it was delivered with (at most the 1 the recorder subscribed with).
    pub(crate) qos: u64,
    /// Whether it came as a retained message.
    pub(crate) retain: bool,
    /// The payload.
    pub(crate) payload: Vec<u8>,
}

impl Message {
    /// The payload as text (plain mode's JSON).
    pub(crate) fn text(&self) -> String {
        String::from_utf8_lossy(&self.payload).into_owned()
    }
}

/// `record.py` subscribed to `spBv1.0/#` (and more filters) on a broker; killed on drop.
pub(crate) struct Recorder {
    proc: Proc,
    path: PathBuf,
}

impl Recorder {
    /// Starts recording into `dir/recording.jsonl` once it has subscribed.
    ///
    /// # Panics
    /// If it does not say `READY` within 10 s.
    pub(crate) fn start(broker: &Broker, dir: &Path, filters: &[&str]) -> Recorder {
        let path = dir.join("recording.jsonl");
        let mut command = Command::new(python());
        command.arg(script("record.py")).args(["--port", &broker.port().to_string(), "--out"]).arg(&path);
        for filter in filters {
            command.args(["--filter", filter]);
        }
        let proc = Proc::spawn("record.py", &mut command);
        proc.wait_for(Stream::Out, |l| l == "READY", Duration::from_secs(10));
        Recorder { proc, path }
    }

    /// The recording's path.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// What it has recorded so far.
    pub(crate) fn messages(&self) -> Vec<Message> {
        messages_in(&self.path)
    }

    /// Waits until `done` holds for the messages so far, and returns them.
    ///
    /// # Panics
    /// If it does not within `within`; the message says `what` and where the recording is.
    pub(crate) fn wait_until(&self, what: &str, within: Duration, done: impl Fn(&[Message]) -> bool) -> Vec<Message> {
        let deadline = Instant::now() + within;
        loop {
            let messages = self.messages();
            if done(&messages) {
                return messages;
            }
            assert!(
                Instant::now() < deadline,
                "waited {within:?} for {what}; {} messages recorded in {}:\n{}\nrecorder:\n{}",
                messages.len(),
                self.path.display(),
                listing(&messages),
                self.proc.log()
            );
            thread::sleep(Duration::from_millis(50));
        }
    }

    /// Stops it (SIGTERM: it flushes and leaves) and returns the recording's path.
    pub(crate) fn stop(mut self) -> PathBuf {
        self.proc.terminate();
        self.path.clone()
    }
}

/// The messages of a recording (lines that do not parse are left out).
pub(crate) fn messages_in(recording: &Path) -> Vec<Message> {
    let text = std::fs::read_to_string(recording).unwrap_or_default();
    text.lines().filter_map(|line| serde_json::from_str::<Value>(line).ok()).filter_map(|v| message(&v)).collect()
}

fn message(line: &Value) -> Option<Message> {
    let payload = line.get("payload")?.as_str()?;
    let bytes: Option<Vec<u8>> =
        (0..payload.len() / 2).map(|i| u8::from_str_radix(payload.get(2 * i..2 * i + 2)?, 16).ok()).collect();
    Some(Message {
        topic: line.get("topic")?.as_str()?.to_string(),
        qos: line.get("qos")?.as_u64()?,
        retain: line.get("retain")?.as_bool()?,
        payload: bytes?,
    })
}

/// One line per message: the topic, QoS, retain and size (failure messages).
pub(crate) fn listing(messages: &[Message]) -> String {
    messages.iter().fold(String::new(), |mut text, m| {
        let _ = writeln!(text, "  {} qos {} retain {} {} bytes", m.topic, m.qos, m.retain, m.payload.len());
        text
    })
}

/// How many messages have a topic of this Sparkplug message type (`"DBIRTH"`, ...) or,
/// with a device id, of that device.
pub(crate) fn count(messages: &[Message], kind: &str, device: Option<&str>) -> usize {
    messages.iter().filter(|m| is(m, kind, device)).count()
}

/// Whether `m` is a Sparkplug message of type `kind` (for `device`, if given).
pub(crate) fn is(m: &Message, kind: &str, device: Option<&str>) -> bool {
    let parts: Vec<&str> = m.topic.split('/').collect();
    parts.first() == Some(&"spBv1.0") && parts.get(2) == Some(&kind) && device.is_none_or(|d| parts.get(4) == Some(&d))
}

/// What `verify.py` said about a recording.
pub(crate) struct Verdict {
    /// Its JSON summary.
    pub(crate) summary: Value,
    /// Its exit code: 0 no rule broken, 1 some.
    pub(crate) code: i32,
    /// The recording it read.
    pub(crate) recording: PathBuf,
}

impl Verdict {
    /// The rules broken, as verify.py words them.
    pub(crate) fn errors(&self) -> Vec<String> {
        strings(self.summary.get("errors"))
    }

    /// Asserts that no rule is broken.
    #[track_caller]
    pub(crate) fn assert_clean(&self) {
        assert!(self.code == 0 && self.errors().is_empty(), "verify.py found errors:\n{self}");
    }

    /// The sessions (NBIRTH to NDEATH or the next NBIRTH) with their bdSeq.
    pub(crate) fn sessions(&self) -> Vec<Value> {
        self.summary.get("sessions").and_then(Value::as_array).cloned().unwrap_or_default()
    }

    /// `summary.devices[device].metrics[metric][key]`.
    pub(crate) fn metric(&self, device: &str, metric: &str, key: &str) -> Value {
        self.summary
            .pointer(&format!("/devices/{device}/metrics/{}/{key}", metric.replace('/', "~1")))
            .cloned()
            .unwrap_or(Value::Null)
    }

    /// The recorded values of `device/metric` (asked for with `--series`).
    pub(crate) fn series(&self, device: &str, metric: &str) -> Vec<Value> {
        let key = format!("{device}/{metric}").replace('~', "~0").replace('/', "~1");
        self.summary.pointer(&format!("/series/{key}")).and_then(Value::as_array).cloned().unwrap_or_default()
    }

    /// How many metrics were marked historical.
    pub(crate) fn historical_count(&self) -> usize {
        self.summary.get("historical").and_then(Value::as_u64).map_or(0, |n| usize::try_from(n).unwrap_or(usize::MAX))
    }

    /// `summary.by_type[kind]`, 0 when absent.
    pub(crate) fn messages_of(&self, kind: &str) -> u64 {
        self.summary.pointer(&format!("/by_type/{kind}")).and_then(Value::as_u64).unwrap_or(0)
    }
}

impl std::fmt::Display for Verdict {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let text = serde_json::to_string_pretty(&self.summary).unwrap_or_default();
        write!(f, "recording: {}\nverify.py exit {}, summary:\n{text}", self.recording.display(), self.code)
    }
}

fn strings(value: Option<&Value>) -> Vec<String> {
    value
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(|v| v.as_str().map(String::from)).collect())
        .unwrap_or_default()
}

/// Runs `verify.py RECORDING ARGS...` and returns its summary. The summary is also written
/// next to the recording (`verify.json`).
///
/// # Panics
/// If verify.py cannot run, or prints no JSON (exit 2: it could not read the recording).
pub(crate) fn verify(recording: &Path, args: &[&str]) -> Verdict {
    let mut command = Command::new(python());
    command.arg(script("verify.py")).arg(recording).args(args);
    let output = output_within(&mut command, "", Duration::from_secs(60));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let summary: Value = serde_json::from_str(&stdout).unwrap_or_else(|e| {
        panic!(
            "verify.py {} printed no JSON summary ({e}), exit {:?}:\n{stdout}\n{}",
            recording.display(),
            output.status.code(),
            String::from_utf8_lossy(&output.stderr)
        )
    });
    if let Some(dir) = recording.parent() {
        let _ = std::fs::write(dir.join("verify.json"), stdout.as_bytes());
    }
    Verdict { summary, code: output.status.code().unwrap_or(-1), recording: recording.to_path_buf() }
}

/// Runs `publish.py --port P ARGS...` against `broker`.
///
/// # Panics
/// If it fails or takes more than 30 s.
pub(crate) fn publish(broker: &Broker, args: &[&str]) {
    let mut command = Command::new(python());
    command.arg(script("publish.py")).args(["--port", &broker.port().to_string()]).args(args);
    let output = output_within(&mut command, "", Duration::from_secs(30));
    assert!(
        output.status.success(),
        "publish.py {} failed ({:?}):\n{}",
        args.join(" "),
        output.status.code(),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// `protoc --decode_raw` of `payload`: the fields by number, with no schema.
///
/// # Panics
/// If protoc fails (the payload is not protobuf).
pub(crate) fn decode_raw(payload: &[u8], dir: &Path, name: &str) -> String {
    let file = dir.join(format!("{name}.bin"));
    std::fs::write(&file, payload).unwrap_or_else(|e| panic!("writing {}: {e}", file.display()));
    let input = std::fs::File::open(&file).unwrap_or_else(|e| panic!("opening {}: {e}", file.display()));
    let output = Command::new("protoc")
        .arg("--decode_raw")
        .stdin(input)
        .output()
        .unwrap_or_else(|e| panic!("running protoc: {e}"));
    let text = String::from_utf8_lossy(&output.stdout).into_owned();
    assert!(
        output.status.success(),
        "protoc --decode_raw < {} failed: {}",
        file.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    let _ = std::fs::write(dir.join(format!("{name}.decode_raw.txt")), &text);
    text
}
