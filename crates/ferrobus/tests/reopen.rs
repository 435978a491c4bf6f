//! Reopening a lost serial port only while its path names the same device, on real ptys: a
//! raw `/dev/pts/N` is never reopened, even when the next pty gets the number; a symlink (a
//! name chosen for the device, as socat's `link=`) is reopened wherever it leads; and
//! `with_reopen(false)` reopens nothing. [`SameDevice`], the rule itself, is tested as a
//! program that opens a port itself (the bridge's listen-only line) uses it.
#![cfg(unix)] // on ptys and symlinks

use std::path::{Path, PathBuf};
use std::time::Duration;

use ferrobus::port::SameDevice;
use ferrobus::{Client, ClientConfig, Error, Pty, SerialConfig, Transport};
use ferrobus_proto::frame::{LineConfig, Parity};
use tokio::io::AsyncReadExt;

fn transport(path: &Path) -> Transport {
    let line = LineConfig::new(9600).unwrap().with_parity(Parity::None);
    Transport::rtu(SerialConfig::new(path, line))
}

fn config() -> ClientConfig {
    ClientConfig { timeout: Duration::from_millis(100), retries: 0, backoff: None, ..ClientConfig::default() }
}

/// The tests here make and close ptys: one at a time, so that none takes another's number.
static ONE_AT_A_TIME: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Makes ptys until one gets `path`: Linux gives the lowest free number, once the kernel has
/// released the closed pty (it does so a moment later, from a work queue). The ptys holding
/// other numbers are kept meanwhile, then closed.
async fn pty_numbered(path: &Path) -> Pty {
    let mut others = Vec::new();
    for _ in 0..200 {
        let pty = Pty::open().unwrap();
        if pty.path == path {
            return pty;
        }
        others.push(pty);
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    panic!("no new pty got the number of {} in 200 tries (another program took it?)", path.display());
}

/// Bytes the pty's other end wrote within 50 ms (none, if nobody wrote).
async fn written(pty: &mut Pty) -> Vec<u8> {
    let mut buf = [0u8; 64];
    match tokio::time::timeout(Duration::from_millis(50), pty.read(&mut buf)).await {
        Ok(Ok(n)) => buf[..n].to_vec(),
        _ => Vec::new(),
    }
}

/// Closes the pty under the client and makes sure the client has seen it go: the request
/// fails (the write or read hits the hung-up pty, or the reopen is refused).
async fn lose(client: &Client, pty: Pty) {
    drop(pty);
    let lost = client.read_holding_registers(1, 0, 1).await;
    assert!(matches!(lost, Err(Error::Io { .. } | Error::NotSameDevice { .. })), "on a vanished pty: {lost:?}");
}

#[tokio::test]
async fn a_reused_pty_number_is_not_reopened_and_the_new_pty_is_left_alone() {
    let _turn = ONE_AT_A_TIME.lock().await;
    let first = Pty::open().unwrap();
    let path = first.path.clone();
    let client = Client::connect(transport(&path), config()).await.unwrap();
    lose(&client, first).await;
    let mut second = pty_numbered(&path).await;
    let refused = client.read_holding_registers(1, 0, 1).await;
    match &refused {
        Err(Error::NotSameDevice { lasting: true, reason, .. }) => {
            assert!(reason.contains(&format!("{} was a pty", path.display())), "{reason}");
        }
        other => panic!("a request after {} went to another pty: {other:?}", path.display()),
    }
    assert_eq!(written(&mut second).await, [], "nothing was written to the pty that took the number");
    assert!(
        refused.unwrap_err().to_string().starts_with(&format!("not reopening {}", path.display())),
        "the message names the port"
    );
}

/// A symlink in a fresh directory, to `target`.
struct Link {
    dir: PathBuf,
    path: PathBuf,
}

impl Link {
    fn to(target: &Path, name: &str) -> Link {
        let dir = std::env::temp_dir().join(format!("ferrobus-reopen-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir(&dir).unwrap();
        let path = dir.join("line");
        std::os::unix::fs::symlink(target, &path).unwrap();
        Link { dir, path }
    }

    fn point_to(&self, target: &Path) {
        std::fs::remove_file(&self.path).unwrap();
        std::os::unix::fs::symlink(target, &self.path).unwrap();
    }
}

impl Drop for Link {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

#[tokio::test]
async fn a_symlink_is_a_stable_name_and_is_reopened_wherever_it_leads() {
    let _turn = ONE_AT_A_TIME.lock().await;
    let first = Pty::open().unwrap();
    let link = Link::to(&first.path, "named");
    let client = Client::connect(transport(&link.path), config()).await.unwrap();
    lose(&client, first).await;
    let mut second = Pty::open().unwrap();
    link.point_to(&second.path);
    let timed_out = client.read_holding_registers(1, 0, 1).await;
    assert!(matches!(timed_out, Err(Error::Timeout { .. })), "nobody answers on the new pty: {timed_out:?}");
    assert_eq!(written(&mut second).await, [0x01, 0x03, 0x00, 0x00, 0x00, 0x01, 0x84, 0x0A], "the request went out");
}

#[tokio::test]
async fn without_reopening_a_lost_port_stays_lost() {
    let _turn = ONE_AT_A_TIME.lock().await;
    let first = Pty::open().unwrap();
    let link = Link::to(&first.path, "off");
    let client = Client::connect(transport(&link.path).with_reopen(false), config()).await.unwrap();
    lose(&client, first).await;
    let mut second = Pty::open().unwrap();
    link.point_to(&second.path);
    let refused = client.read_holding_registers(1, 0, 1).await;
    let message = refused.as_ref().map_err(ToString::to_string).unwrap_err();
    assert!(matches!(refused, Err(Error::Io { .. })), "{refused:?}");
    assert!(message.contains("reopening is off"), "{message}");
    assert_eq!(written(&mut second).await, [], "the port was not reopened");
}

#[tokio::test]
async fn same_device_opens_a_pty_until_its_number_is_another_ptys_and_a_symlink_wherever_it_leads() {
    let _turn = ONE_AT_A_TIME.lock().await;
    let first = Pty::open().unwrap();
    let path = first.path.clone();
    let mut same = SameDevice::new(&path);
    // A failed open remembers nothing; the first that succeeds remembers the pty.
    assert_eq!(same.open(|| Err::<(), _>("busy")).unwrap(), Err("busy"));
    assert_eq!(same.open(|| Ok::<_, ()>(1)).unwrap(), Ok(1));
    drop(first);
    let _second = pty_numbered(&path).await;
    let refused = same.open(|| -> Result<(), ()> { panic!("another pty's line must not be touched") }).unwrap_err();
    assert!(refused.lasting(), "a pty never comes back: {refused}");
    assert!(refused.to_string().contains("was a pty"), "{refused}");

    let target = Pty::open().unwrap();
    let link = Link::to(&target.path, "same-device");
    let mut named = SameDevice::new(&link.path);
    assert!(named.open(|| Ok::<_, ()>(())).is_ok());
    let other = Pty::open().unwrap();
    link.point_to(&other.path);
    assert_eq!(named.open(|| Ok::<_, ()>("reopened")).unwrap(), Ok("reopened"), "a name chosen for the device");
}
