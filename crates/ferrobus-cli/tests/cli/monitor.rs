//! `ferrobus monitor` in a real terminal emulator: tmux on a private socket, driving the
//! monitor against `ferrobus sim --profile generic` over Modbus/TCP. It starts, shows a value
//! written by another client, writes a register through its edit and confirm keys (read back
//! with `ferrobus read`), quits, and the shell's prompt is back off the alternate screen.

use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use std::io::{BufRead, BufReader};

/// How long the screen may take to show something before the test fails (a failure
/// deadline, not a timing figure).
const PATIENCE: Duration = Duration::from_secs(30);

/// A tmux server on its own socket, killed (that server only) on drop.
struct Tmux {
    socket: String,
}

impl Tmux {
    fn cmd(&self, args: &[&str]) -> Output {
        Command::new("tmux").arg("-L").arg(&self.socket).args(args).output().expect("tmux runs")
    }

    fn screen(&self) -> String {
        String::from_utf8_lossy(&self.cmd(&["capture-pane", "-p", "-t", "m"]).stdout).into_owned()
    }

    fn keys(&self, keys: &[&str]) {
        let mut args = vec!["send-keys", "-t", "m"];
        args.extend_from_slice(keys);
        assert!(self.cmd(&args).status.success(), "tmux send-keys {keys:?}");
    }

    /// Waits until the screen satisfies `ok`; fails with the last screen.
    fn wait_for(&self, what: &str, ok: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + PATIENCE;
        loop {
            let screen = self.screen();
            if ok(&screen) {
                return screen;
            }
            assert!(Instant::now() < deadline, "the screen never showed {what}; it shows:\n{screen}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    fn alternate_screen(&self) -> String {
        String::from_utf8_lossy(&self.cmd(&["display-message", "-p", "-t", "m", "#{alternate_on}"]).stdout)
            .trim()
            .to_string()
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = self.cmd(&["kill-server"]);
    }
}

fn have_tmux() -> bool {
    let found = Command::new("tmux").arg("-V").output().is_ok_and(|o| o.status.success());
    let ci = matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"));
    assert!(found || !ci, "tmux is missing; .ci/setup-peers.sh installs it (CI=true: a missing peer is a failure)");
    found
}

struct Sim(Child);

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start_sim() -> (Sim, String) {
    start_sim_of("generic")
}

fn start_sim_of(profile: &str) -> (Sim, String) {
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
    let addr = format!("127.0.0.1:{port}");
    let mut child = Command::new(env!("CARGO_BIN_EXE_ferrobus"))
        .args(["--tcp", &addr, "sim", "--profile", profile, "--duration", "120s"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ferrobus sim starts");
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    loop {
        let line = lines.next().expect("the sim says where it listens").unwrap();
        if line.starts_with("sim: listening on ") {
            break;
        }
    }
    std::thread::spawn(move || lines.map_while(Result::ok).for_each(drop));
    (Sim(child), addr)
}

fn ferrobus(addr: &str, args: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrobus")).args(["--tcp", addr]).args(args).output().unwrap();
    assert!(out.status.success(), "ferrobus {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn monitor_in_tmux_shows_live_values_writes_a_register_the_sim_takes_and_restores_the_terminal() {
    if !have_tmux() {
        return;
    }
    let (_sim, addr) = start_sim();
    let tmux = Tmux { socket: format!("ferrobus-monitor-{}", std::process::id()) };
    let started = tmux.cmd(&["new-session", "-d", "-s", "m", "-x", "100", "-y", "30", "env", "PS1=prompt$ ", "sh"]);
    assert!(started.status.success(), "tmux new-session: {}", String::from_utf8_lossy(&started.stderr));
    tmux.wait_for("the shell's prompt", |s| s.contains("prompt$"));
    let command = format!("{} --tcp {addr} monitor holding:0:8@100ms --alias 5=speed", env!("CARGO_BIN_EXE_ferrobus"));
    tmux.keys(&[&command, "Enter"]);
    tmux.wait_for("the pane and its first good read", |s| {
        s.contains("unit 1 holding 0x0000 ×8 every 100 ms") && s.contains("Err 0") && !s.contains("Tx 0 ")
    });
    assert_eq!(tmux.alternate_screen(), "1", "the monitor draws on the alternate screen");

    // Another client writes; the grid shows it.
    ferrobus(&addr, &["write", "register", "5", "4321"]);
    tmux.wait_for("register 5 = 4321 under its alias", |s| {
        s.lines().any(|l| l.contains("0005 speed") && l.contains("4321"))
    });

    // Edit register 2 in place: move to it, e, type, Enter, then y to confirm.
    tmux.keys(&["Right", "Right", "e"]);
    tmux.keys(&["-l", "1234"]);
    tmux.keys(&["Enter"]);
    tmux.wait_for("the confirmation", |s| s.contains("write 1234 (registers [0x04d2]) to unit 1 0x0002? y/n"));
    tmux.keys(&["y"]);
    tmux.wait_for("the write's result", |s| s.contains("wrote 0x0002 on unit 1"));
    let read = ferrobus(&addr, &["read", "holding", "2"]);
    assert!(read.lines().any(|l| l.contains("0x04D2") && l.contains("1234")), "the sim did not take it:\n{read}");
    tmux.wait_for("the traffic pane's FC06", |s| s.contains("Tx u1 06 00 02 04 D2"));

    // Quit: the shell's prompt is back, off the alternate screen.
    tmux.keys(&["q"]);
    let screen =
        tmux.wait_for("the prompt after the monitor", |s| s.lines().filter(|l| l.starts_with("prompt$")).count() >= 2);
    assert!(!screen.contains("ferrobus monitor  tcp"), "the monitor's screen is left behind:\n{screen}");
    assert_eq!(tmux.alternate_screen(), "0", "the alternate screen is still on");
    // The terminal is back in cooked mode: the shell echoes what is typed and runs it.
    tmux.keys(&["echo restored-$((40+2))", "Enter"]);
    tmux.wait_for("the shell running a command", |s| s.contains("restored-42"));
}

#[test]
fn monitor_in_tmux_restores_the_terminal_on_sigterm() {
    if !have_tmux() {
        return;
    }
    let (_sim, addr) = start_sim();
    let tmux = Tmux { socket: format!("ferrobus-monitor-term-{}", std::process::id()) };
    let started = tmux.cmd(&["new-session", "-d", "-s", "m", "-x", "80", "-y", "24", "env", "PS1=prompt$ ", "sh"]);
    assert!(started.status.success(), "tmux new-session: {}", String::from_utf8_lossy(&started.stderr));
    tmux.wait_for("the shell's prompt", |s| s.contains("prompt$"));
    let pidfile = std::env::temp_dir().join(format!("ferrobus-monitor-{}.pid", std::process::id()));
    let command = format!(
        "sh -c 'echo $$ > {}; exec {} --tcp {addr} monitor holding:0:4@100ms'",
        pidfile.display(),
        env!("CARGO_BIN_EXE_ferrobus")
    );
    tmux.keys(&[&command, "Enter"]);
    tmux.wait_for("the monitor", |s| s.contains("unit 1 holding 0x0000 ×4") && s.contains("q quit"));
    let pid = std::fs::read_to_string(&pidfile).unwrap().trim().to_string();
    let _ = std::fs::remove_file(&pidfile);
    assert!(Command::new("kill").args(["-TERM", &pid]).status().unwrap().success());
    tmux.wait_for("the prompt after SIGTERM", |s| s.lines().filter(|l| l.starts_with("prompt$")).count() >= 2);
    assert_eq!(tmux.alternate_screen(), "0", "SIGTERM left the alternate screen on");
    tmux.keys(&["echo restored-$((40+2))", "Enter"]);
    tmux.wait_for("the shell running a command", |s| s.contains("restored-42"));
}

#[test]
fn monitor_refuses_a_pipe_and_a_bad_definition_with_the_reason_before_opening_the_bus() {
    // Port 9 on loopback has nothing listening: the refusals come before any connection.
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_ferrobus"))
            .args(["--tcp", "127.0.0.1:9", "monitor"])
            .args(args)
            .stdin(Stdio::null())
            .output()
            .unwrap()
    };
    let out = run(&["holding:0:4"]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(String::from_utf8_lossy(&out.stderr).contains("monitor needs a terminal"), "{out:?}");
    let out = run(&["holding:0:126"]);
    assert_eq!(out.status.code(), Some(2), "{out:?}");
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("'holding:0:126': the count is 1 to 125 for holding"),
        "{out:?}"
    );
    let out = run(&["holding:0:4", "--format", "7=f32"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("no pane shows address 0x0007"), "{out:?}");
    let out = run(&[]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("give what to watch"), "{out:?}");
}

#[test]
fn monitor_in_tmux_restores_the_terminal_on_a_panic_and_prints_the_panic_message() {
    if !have_tmux() {
        return;
    }
    let (_sim, addr) = start_sim();
    let tmux = Tmux { socket: format!("ferrobus-monitor-panic-{}", std::process::id()) };
    let started = tmux.cmd(&["new-session", "-d", "-s", "m", "-x", "80", "-y", "24", "env", "PS1=prompt$ ", "sh"]);
    assert!(started.status.success(), "tmux new-session: {}", String::from_utf8_lossy(&started.stderr));
    tmux.wait_for("the shell's prompt", |s| s.contains("prompt$"));
    // The trigger is in debug builds only (the test binary's ferrobus is one): `!` panics.
    let command = format!(
        "RUST_BACKTRACE=0 FERROBUS_MONITOR_TEST_PANIC=1 {} --tcp {addr} monitor holding:0:4@100ms",
        env!("CARGO_BIN_EXE_ferrobus")
    );
    tmux.keys(&[&command, "Enter"]);
    tmux.wait_for("the monitor", |s| s.contains("unit 1 holding 0x0000 ×4") && s.contains("q quit"));
    assert_eq!(tmux.alternate_screen(), "1", "the monitor draws on the alternate screen");
    tmux.keys(&["!"]);
    let screen =
        tmux.wait_for("the prompt after the panic", |s| s.lines().filter(|l| l.starts_with("prompt$")).count() >= 2);
    assert!(
        screen.contains("FERROBUS_MONITOR_TEST_PANIC is set: the monitor panics as the test asked"),
        "the panic's message is not on the screen (stderr):\n{screen}"
    );
    assert!(!screen.contains("q quit"), "the monitor's screen is left behind:\n{screen}");
    assert_eq!(tmux.alternate_screen(), "0", "the panic left the alternate screen on");
    // Cooked mode again: the shell echoes what is typed and runs it.
    tmux.keys(&["echo restored-$((40+2))", "Enter"]);
    tmux.wait_for("the shell running a command", |s| s.contains("restored-42"));
}

#[test]
fn monitor_reads_3g3rx_points_far_apart_through_the_planner_with_no_exception() {
    if !have_tmux() {
        return;
    }
    // The simulated 3G3RX answers exception 02 to a read of any unmapped register, and reads
    // at most 4 registers a request: one raw range from d001 to F002 would fail every poll.
    let (_sim, addr) = start_sim_of("omron-3g3rx");
    let tmux = Tmux { socket: format!("ferrobus-monitor-plan-{}", std::process::id()) };
    let command = format!(
        "{} --tcp {addr} --device omron-3g3rx monitor F002@200ms A003@200ms 'd00*@200ms'",
        env!("CARGO_BIN_EXE_ferrobus")
    );
    let started = tmux.cmd(&["new-session", "-d", "-s", "m", "-x", "100", "-y", "40", &command]);
    assert!(started.status.success(), "tmux new-session: {}", String::from_utf8_lossy(&started.stderr));
    let screen = tmux.wait_for("every pane polled at least twice", |s| {
        let tx: Vec<u64> = s
            .lines()
            .filter_map(|l| l.split("│Tx ").nth(1))
            .filter_map(|t| t.split_whitespace().next()?.parse().ok())
            .collect();
        tx.len() == 3 && tx.iter().all(|n| *n >= 2)
    });
    for line in screen.lines().filter(|l| l.contains("│Tx ")) {
        assert!(line.contains("Err 0 (timeout 0, CRC 0, exception 0, other 0)"), "a poll failed: {line}\n{screen}");
    }
    // Each pane at the planner's reads: F002 (2 registers) and A003 alone, d00* in 4-register reads.
    assert!(screen.contains("unit 1 holding 0x1102 ×2 every 200 ms"), "{screen}");
    assert!(screen.contains("unit 1 holding 0x1202 ×1 every 200 ms"), "{screen}");
    assert!(screen.contains("unit 1 holding 0x1000 ×13 in 4 reads every 200 ms"), "{screen}");
    assert!(screen.contains("Tx u1 03 10 00 00 04"), "the traffic shows the first 4-register read:\n{screen}");
    // The values scaled, with their units (the simulator's power-on values).
    assert!(screen.contains("1102 accelera    10.00 s"), "{screen}");
    assert!(screen.contains("1202 base fre      60 Hz"), "{screen}");
    assert!(screen.contains("1000 output f    0.00 Hz"), "{screen}");
    tmux.keys(&["q"]);
}

#[test]
fn monitor_edit_takes_a_run_locked_parameter_stopped_and_refuses_it_running_with_the_guards_words() {
    if !have_tmux() {
        return;
    }
    let (_sim, addr) = start_sim_of("omron-3g3rx");
    let tmux = Tmux { socket: format!("ferrobus-monitor-guard-{}", std::process::id()) };
    let command = format!("{} --tcp {addr} --device omron-3g3rx monitor A003@200ms", env!("CARGO_BIN_EXE_ferrobus"));
    let started = tmux.cmd(&["new-session", "-d", "-s", "m", "-x", "120", "-y", "30", &command]);
    assert!(started.status.success(), "tmux new-session: {}", String::from_utf8_lossy(&started.stderr));
    tmux.wait_for("A003 polled", |s| s.contains("1202 base fre      60 Hz"));
    let edit = |value: &str| {
        tmux.keys(&["e"]);
        tmux.keys(&["-l", value]);
        tmux.keys(&["Enter"]);
        tmux.wait_for("the confirmation", |s| s.contains("to unit 1 0x1202? y/n"));
        tmux.keys(&["y"]);
    };
    let a003 = || ferrobus(&addr, &["--device", "omron-3g3rx", "get", "A003"]);

    // Stopped: written.
    edit("50");
    tmux.wait_for("the write's result", |s| s.contains("wrote 0x1202 on unit 1"));
    assert!(a003().contains("50 Hz"), "the sim did not take it:\n{}", a003());

    // Running: refused in the guard's words, nothing written.
    crate::guard::make_it_run(&addr);
    edit("55");
    let screen = tmux.wait_for("the refusal", |s| s.contains("not written: A003 cannot change"));
    assert!(screen.contains(&format!("not written: {}", crate::guard::REFUSAL)), "{screen}");
    assert!(a003().contains("50 Hz"), "a refused edit changed A003:\n{}", a003());
    tmux.keys(&["q"]);
}
