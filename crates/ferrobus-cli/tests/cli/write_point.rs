//! Every writer of a named point sends it in the request the device takes, because they all
//! write it one way (`ferrobus_tools::write`): against a simulated device whose profile answers
//! neither FC05 nor FC06 (the simulator refuses them with exception 01, as its profile says),
//! `set` writes a coil with FC0F and a word with FC10, and `restore --apply` writes the backup
//! back with FC10 (it sent FC06 before, which such a device refuses). The library's writers
//! (a poll handle, the bridge's path) are shown the same in the ferrobus crate's
//! `tests/write_point.rs`; the monitor's edit in `monitor.rs`.

use assert_cmd::assert::OutputAssertExt;

use crate::backup::{TcpSim, temp};
use crate::server::{ferrobus, stderr, stdout};

const PROFILE: &str = "[device]\nname = 'no-fc06'\nvendor = 'v'\nproduct_code = 'p'\nrevision = '1'\n\
    [comm]\nfunctions = [0x01, 0x03, 0x0F, 0x10]\n\
    [[coils]]\nnumber = 0\nname = 'run'\naccess = 'rw'\nbackup = false\n\
    [[registers]]\nnumber = 0\nname = 'speed'\naccess = 'rw'\nmax = 1000\n\
    [[registers]]\nnumber = 1\nname = 'accel'\naccess = 'rw'\nmax = 1000\n";

fn speed(sim: &TcpSim, device: &str) -> String {
    let out = stdout(&sim.run(device, &["get", "speed", "--json"]).success());
    let doc: serde_json::Value = serde_json::from_str(&out).unwrap();
    doc.pointer("/points/0/value").map(ToString::to_string).unwrap_or_default()
}

#[test]
fn set_and_restore_write_a_device_without_fc05_and_fc06_with_fc0f_and_fc10() {
    let (profile, backup) = (temp("no-fc06.toml"), temp("no-fc06-backup.toml"));
    std::fs::write(&profile, PROFILE).unwrap();
    let (device, file) = (profile.to_str().unwrap(), backup.to_str().unwrap());
    let sim = TcpSim::start(&["--profile", device]);

    // The device as its profile says: FC06 refused.
    let refused = stderr(&ferrobus().args(["--tcp", &sim.addr, "write", "register", "0", "5"]).assert().code(1));
    assert!(refused.contains("answered 0x06 Write Single Register with exception 0x01"), "{refused}");
    let before = sim.functions().len();

    sim.run(device, &["set", "speed", "42"]).success();
    sim.run(device, &["set", "run", "1"]).success();
    let sent: Vec<u8> = sim.functions()[before..].iter().copied().filter(|f| ![0x01, 0x03].contains(f)).collect();
    assert_eq!(sent, [0x10, 0x0F], "a word with FC10, a coil with FC0F");
    assert_eq!(speed(&sim, device), "\"42\"");

    sim.run(device, &["backup", "-o", file]).success();
    sim.run(device, &["set", "speed", "7"]).success();
    let before = sim.functions().len();
    sim.run(device, &["restore", file, "--apply"]).success();
    let sent: Vec<u8> = sim.functions()[before..].iter().copied().filter(|f| ![0x01, 0x03].contains(f)).collect();
    assert_eq!(sent, [0x10], "restore wrote speed back with FC10");
    assert_eq!(speed(&sim, device), "\"42\"");
    for path in [profile, backup] {
        std::fs::remove_file(path).unwrap();
    }
}
