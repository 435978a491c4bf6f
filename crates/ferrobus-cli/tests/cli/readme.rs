//! The README's tour runs as written: its one `sh` block, taken from README.md as it stands, is
//! run by bash with `-e` (every command must succeed) and the binary under test first on the
//! PATH, in a directory of its own. The one change made to it is the simulator's TCP port,
//! 1502 in the README, moved to a free one so that the test runs beside others.

use std::process::Command;

/// The lines of the fenced `sh` block under `## A tour`.
fn tour(readme: &str) -> String {
    let section = readme.split("\n## A tour\n").nth(1).expect("README.md has a '## A tour' section");
    let block = section.split("```sh\n").nth(1).expect("the tour has a ```sh block");
    block.split("\n```").next().expect("the block ends").to_string()
}

#[test]
fn the_readme_tour_runs_as_written_against_its_simulated_drive() {
    let readme = include_str!("../../../../README.md");
    let block = tour(readme);
    assert!(block.lines().filter(|l| l.starts_with("ferrobus ")).count() >= 10, "a tour of ten commands:\n{block}");
    assert!(block.contains("127.0.0.1:1502"), "the tour's simulator listens on 127.0.0.1:1502:\n{block}");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let script = block.replace("127.0.0.1:1502", &format!("127.0.0.1:{port}"));
    let bin = std::path::Path::new(env!("CARGO_BIN_EXE_ferrobus")).parent().unwrap().to_path_buf();
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let dir = std::env::temp_dir().join(format!("ferrobus-cli-tour-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    // A command that fails ends the script: the simulator goes with it.
    let script = format!("trap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n{script}\n");
    let out =
        Command::new("bash").arg("-e").arg("-c").arg(&script).env("PATH", path).current_dir(&dir).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "the tour failed ({}):\n{script}\nstdout:\n{stdout}\nstderr:\n{stderr}", out.status);
    // What the tour says each step shows.
    assert!(stdout.contains("base frequency"), "get names the parameters:\n{stdout}");
    assert!(stdout.contains("written, verified"), "restore --apply verifies:\n{stdout}");
    assert!(dir.join("drive.toml").is_file(), "backup -o drive.toml wrote the file");
    assert!(stderr.contains("0 exceptions"), "the simulator's counters at the end:\n{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}
