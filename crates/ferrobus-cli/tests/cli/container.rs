//! The container image (Dockerfile, scripts/image-root.sh) and the compose example
//! (examples/container/). Everywhere: the image's root, laid out by the script the Dockerfile
//! runs, holds a `ferrobus` that runs, the profiles and the store; the compose file's commands
//! are ones `ferrobus` takes and its plant file checks. Where docker or podman can build, the
//! image is built and run: `--version`, as a user without privileges, and a simulated drive in
//! the container read from here. Without a container runtime, or with one that can neither
//! find nor fetch the images the Dockerfile builds from, that test says SKIPPED and why.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::config::Scratch;

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn said(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

#[test]
fn the_image_root_holds_a_ferrobus_that_runs_the_profiles_and_a_store_for_the_bridge() {
    let dir = Scratch::new("image-root");
    let root = dir.0.join("rootfs");
    let out = Command::new("bash")
        .arg(repo().join("scripts/image-root.sh"))
        .args(["--bin", env!("CARGO_BIN_EXE_ferrobus"), "--out"])
        .arg(&root)
        .output()
        .unwrap();
    assert!(out.status.success(), "image-root.sh: {}", said(&out));
    for file in [
        "usr/bin/ferrobus",
        "usr/share/ferrobus/profiles/omron-3g3rx.toml",
        "usr/share/ferrobus/profiles/sdp-servo.toml",
        "usr/share/doc/ferrobus/README.md",
    ] {
        assert!(root.join(file).is_file(), "{file} in the image");
    }
    for folder in ["etc/ferrobus", "var/lib/ferrobus"] {
        assert!(root.join(folder).is_dir(), "{folder} in the image");
    }
    let bin = root.join("usr/bin/ferrobus");
    let version = Command::new(&bin).arg("--version").output().unwrap();
    assert_eq!(String::from_utf8_lossy(&version.stdout), "ferrobus 0.1.0\n");
    let demo = Command::new(&bin).arg("demo").env("XDG_CONFIG_HOME", &dir.0).output().unwrap();
    assert!(demo.status.success() && said(&demo).contains("echoed 0x12 0x34"), "{}", said(&demo));

    let refused = Command::new("bash").arg(repo().join("scripts/image-root.sh")).arg("--bin").output().unwrap();
    assert_eq!(refused.status.code(), Some(2), "{}", said(&refused));
}

#[test]
fn the_compose_example_runs_commands_ferrobus_takes_mounts_files_that_exist_and_a_plant_that_checks() {
    let folder = repo().join("examples/container");
    let text = std::fs::read_to_string(folder.join("compose.yaml")).unwrap();
    let compose: serde_yaml_ng::Value = serde_yaml_ng::from_str(&text).unwrap();
    let services = compose["services"].as_mapping().expect("services");
    let names: Vec<&str> = services.keys().filter_map(|k| k.as_str()).collect();
    assert_eq!(names, ["mosquitto", "drive", "bridge"]);
    let dir = Scratch::new("compose");
    for (name, service) in services {
        for volume in service["volumes"].as_sequence().into_iter().flatten() {
            let source = volume.as_str().unwrap().split(':').next().unwrap();
            if source.starts_with("./") {
                assert!(folder.join(source).is_file(), "{name:?} mounts {source}, which is not there");
            }
        }
        if service["image"].as_str() != Some("ferrobus") {
            continue;
        }
        let command: Vec<&str> =
            service["command"].as_sequence().unwrap().iter().map(|w| w.as_str().unwrap()).collect();
        // --help stops once the command line has parsed, as the image's ferrobus takes it.
        let help = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
            .args(&command)
            .arg("--help")
            .env("XDG_CONFIG_HOME", &dir.0)
            .output()
            .unwrap();
        assert!(help.status.success(), "{name:?}: {command:?}: {}", said(&help));
    }
    // The plant file mounted on /etc/ferrobus/plant.toml checks as it is.
    let check = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
        .args(["bridge", "--check", "--config"])
        .arg(folder.join("plant.toml"))
        .output()
        .unwrap();
    assert!(check.status.success() && said(&check).contains("ok"), "{}", said(&check));
    let dockerfile = std::fs::read_to_string(repo().join("Dockerfile")).unwrap();
    assert!(dockerfile.lines().any(|l| l == "USER nonroot"), "the image runs without privileges");
    assert!(dockerfile.contains("scripts/image-root.sh"), "the image's root is the script's");
}

/// docker or podman, if one answers `info` (a client without a daemon does not) and has or can
/// fetch every image the Dockerfile builds from (a machine without a registry cannot); else
/// why not.
fn container_runtime() -> Result<&'static str, String> {
    let dockerfile = std::fs::read_to_string(repo().join("Dockerfile")).unwrap();
    let bases = base_images(&dockerfile);
    assert!(bases.len() >= 2, "the Dockerfile's FROM lines: {bases:?}");
    let mut why = Vec::new();
    for runtime in ["docker", "podman"] {
        match Command::new(runtime).arg("info").output() {
            Ok(out) if out.status.success() => {}
            Ok(out) => {
                why.push(format!("`{runtime} info` failed: {}", first_line(&out)));
                continue;
            }
            Err(e) => {
                why.push(format!("{runtime}: {e}"));
                continue;
            }
        }
        let missing = bases.iter().find_map(|image| {
            if run(runtime, &["image", "inspect", image]).status.success() {
                return None;
            }
            let out = run(runtime, &["manifest", "inspect", image]);
            (!out.status.success()).then(|| format!("{runtime} cannot fetch {image}: {}", first_line(&out)))
        });
        match missing {
            None => return Ok(runtime),
            Some(missing) => why.push(missing),
        }
    }
    Err(why.join("; "))
}

/// The images a Dockerfile's stages start from (`FROM [--platform=P] IMAGE [AS NAME]`), with
/// its `ARG NAME=DEFAULT` put in for `${NAME}`; a stage built on another stage is none.
fn base_images(dockerfile: &str) -> Vec<String> {
    let mut args: Vec<(String, String)> = Vec::new();
    let mut stages: Vec<String> = Vec::new();
    let mut images = Vec::new();
    for line in dockerfile.lines().map(str::trim) {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("ARG") => {
                if let Some((name, default)) = words.next().and_then(|w| w.split_once('=')) {
                    args.push((name.to_string(), default.to_string()));
                }
            }
            Some("FROM") => {
                let mut words = words.skip_while(|w| w.starts_with("--"));
                let Some(image) = words.next() else { continue };
                let image =
                    args.iter().fold(image.to_string(), |i, (name, value)| i.replace(&format!("${{{name}}}"), value));
                if !stages.contains(&image) {
                    images.push(image);
                }
                if let (Some(as_), Some(name)) = (words.next(), words.next())
                    && as_.eq_ignore_ascii_case("as")
                {
                    stages.push(name.to_string());
                }
            }
            _ => {}
        }
    }
    images
}

#[test]
fn the_dockerfile_builds_from_a_rust_image_and_the_distroless_base() {
    let dockerfile = std::fs::read_to_string(repo().join("Dockerfile")).unwrap();
    assert_eq!(
        base_images(&dockerfile),
        ["docker.io/library/rust:1.95-slim-bookworm", "gcr.io/distroless/cc-debian12:nonroot"]
    );
    let staged = "ARG V=1\nFROM a:${V} AS build\nFROM build\nFROM --platform=$X b AS run\n";
    assert_eq!(base_images(staged), ["a:1", "b"]);
}

/// The first line with something on it of what a command said on stderr.
fn first_line(out: &Output) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr);
    stderr.lines().find(|l| !l.trim().is_empty()).unwrap_or_default().trim().to_string()
}

fn run(runtime: &str, args: &[&str]) -> Output {
    Command::new(runtime).args(args).output().unwrap()
}

#[test]
fn where_a_container_runtime_can_build_the_image_is_built_and_runs_unprivileged_serving_a_simulated_drive() {
    let runtime = match container_runtime() {
        Ok(runtime) => runtime,
        Err(why) => {
            eprintln!("SKIPPED the image build: no container runtime that can build ({why})");
            return;
        }
    };
    let tag = format!("ferrobus-test:{}", std::process::id());
    let root = repo();
    let built = Command::new(runtime).args(["build", "-t", &tag]).arg(&root).output().unwrap();
    assert!(built.status.success(), "{runtime} build: {}", said(&built));
    let version = run(runtime, &["run", "--rm", &tag, "--version"]);
    assert_eq!(String::from_utf8_lossy(&version.stdout), "ferrobus 0.1.0\n", "{}", said(&version));
    let user = run(runtime, &["image", "inspect", "--format", "{{.Config.User}}", &tag]);
    assert_eq!(String::from_utf8_lossy(&user.stdout).trim(), "nonroot");

    let started = run(
        runtime,
        &[
            "run",
            "-d",
            "--rm",
            "-p",
            "127.0.0.1::502",
            &tag,
            "sim",
            "--profile",
            "omron-3g3rx",
            "--unit",
            "1",
            "--tcp",
            "0.0.0.0:502",
        ],
    );
    assert!(started.status.success(), "{}", said(&started));
    let container = String::from_utf8_lossy(&started.stdout).trim().to_string();
    let port = run(runtime, &["port", &container, "502"]);
    let address = String::from_utf8_lossy(&port.stdout).lines().next().unwrap_or_default().trim().to_string();
    // The simulator is up once it answers; a fresh container may take a moment.
    let mut read = None;
    for _ in 0..50 {
        let out = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
            .args(["--tcp", &address, "--device", "omron-3g3rx", "get", "F001"])
            .output()
            .unwrap();
        if out.status.success() {
            read = Some(out);
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
    let _ = run(runtime, &["stop", &container]);
    let _ = run(runtime, &["image", "rm", &tag]);
    let read = read.unwrap_or_else(|| panic!("the simulated drive at {address:?} never answered"));
    assert!(said(&read).contains("F001"), "{}", said(&read));
}
