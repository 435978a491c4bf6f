//! The Debian package: scripts/deb.sh packs this test's binary, `dpkg -x` unpacks it into a
//! scratch root, and the unpacked `ferrobus` runs `--version` and `demo`; the man pages, the
//! completions and the built-in profiles are where Debian's tools look for them.

use std::path::Path;
use std::process::Command;

use crate::config::Scratch;

#[test]
fn the_deb_unpacks_and_its_ferrobus_runs_version_and_demo_with_man_pages_completions_and_profiles() {
    let ci = matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"));
    if Command::new("dpkg-deb").arg("--version").output().is_err() {
        assert!(!ci, "dpkg-deb is missing (CI=true)");
        eprintln!("SKIPPED: dpkg-deb is not installed (not a Debian system)");
        return;
    }
    let dir = Scratch::new("deb");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new("bash")
        .arg(root.join("scripts/deb.sh"))
        .args(["--bin", env!("CARGO_BIN_EXE_ferrobus"), "--compress", "gzip", "--out"])
        .arg(&dir.0)
        .output()
        .unwrap();
    assert!(out.status.success(), "deb.sh: {}", String::from_utf8_lossy(&out.stderr));
    let deb = String::from_utf8(out.stdout).unwrap().trim().to_string();
    assert!(Path::new(&deb).extension().is_some_and(|e| e == "deb") && Path::new(&deb).exists(), "{deb}");

    let info = Command::new("dpkg-deb")
        .args(["--field", &deb, "Package", "Version", "Architecture", "Depends"])
        .output()
        .unwrap();
    let info = String::from_utf8(info.stdout).unwrap();
    assert!(info.contains("Package: ferrobus") && info.contains("Version: 0.1.0"), "{info}");
    assert!(info.contains("Depends: libc6 (>= 2."), "the glibc the binary needs: {info}");

    let unpacked = dir.0.join("root");
    let status = Command::new("dpkg").arg("-x").arg(&deb).arg(&unpacked).status().unwrap();
    assert!(status.success());
    let bin = unpacked.join("usr/bin/ferrobus");
    let version = Command::new(&bin).arg("--version").output().unwrap();
    assert_eq!(String::from_utf8(version.stdout).unwrap(), "ferrobus 0.1.0\n");
    let demo = Command::new(&bin).arg("demo").env("XDG_CONFIG_HOME", &dir.0).output().unwrap();
    assert!(demo.status.success(), "{}", String::from_utf8_lossy(&demo.stderr));
    assert!(
        String::from_utf8_lossy(&demo.stdout).contains("echoed 0x12 0x34"),
        "{}",
        String::from_utf8_lossy(&demo.stdout)
    );

    for file in [
        "usr/share/man/man1/ferrobus.1.gz",
        "usr/share/man/man1/ferrobus-read.1.gz",
        "usr/share/bash-completion/completions/ferrobus",
        "usr/share/zsh/vendor-completions/_ferrobus",
        "usr/share/fish/vendor_completions.d/ferrobus.fish",
        "usr/share/ferrobus/profiles/omron-3g3rx.toml",
        "usr/share/ferrobus/profiles/sdp-servo.toml",
        "usr/share/ferrobus/profiles/generic.toml",
        "usr/share/doc/ferrobus/copyright",
        "usr/lib/systemd/system/ferrobus-gateway.service",
        "usr/lib/systemd/system/ferrobus-bridge.service",
    ] {
        assert!(unpacked.join(file).is_file(), "{file} in the package");
    }
    for unit in ["ferrobus-gateway", "ferrobus-bridge"] {
        let text = std::fs::read_to_string(unpacked.join(format!("usr/lib/systemd/system/{unit}.service"))).unwrap();
        assert!(text.contains("Type=notify") && text.contains("WatchdogSec="), "{unit}: {text}");
        assert!(text.contains("\nExecReload=/bin/kill -HUP $MAINPID\n"), "{unit}: {text}");
        let exec = text.lines().find_map(|l| l.strip_prefix("ExecStart=")).unwrap();
        let mut words = exec.split_whitespace();
        assert_eq!(words.next(), Some("/usr/bin/ferrobus"), "{exec}");
        // The unit's command line parses as the packaged ferrobus takes it (--help stops before running).
        let help = Command::new(&bin).args(words).arg("--help").env("XDG_CONFIG_HOME", &dir.0).output().unwrap();
        assert!(help.status.success(), "{unit}: {exec}: {}", String::from_utf8_lossy(&help.stderr));
    }
    let bash = std::fs::read_to_string(unpacked.join("usr/share/bash-completion/completions/ferrobus")).unwrap();
    assert!(bash.contains("FERROBUS_COMPLETE=\"bash\"") || bash.contains("FERROBUS_COMPLETE="), "{bash}");
}
