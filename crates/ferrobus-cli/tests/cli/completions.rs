//! `ferrobus completions` loaded by bash (`complete -p ferrobus`, then a Tab completed through
//! the script: commands, saved connections, built-in profiles) and by zsh (compdef, and the
//! engine answering zsh's request), the other shells' scripts, and
//! `ferrobus man` rendered by `man -l` without warnings.

use std::process::Command;

use assert_cmd::assert::OutputAssertExt;

use crate::config::Scratch;
use crate::server::{ferrobus, stderr, stdout};

/// Whether a missing tool must fail the test (CI) or may skip it (a developer's machine).
fn required(tool: &str) -> bool {
    if Command::new(tool).arg("--version").output().is_ok() {
        return true;
    }
    let ci = matches!(std::env::var("CI").as_deref(), Ok("true" | "TRUE" | "True" | "1" | "yes"));
    assert!(!ci, "{tool} is missing (CI=true: .ci/setup-peers.sh installs it)");
    eprintln!("SKIPPED: {tool} is not installed");
    false
}

/// The bash script, calling this test's binary.
fn bash_script(dir: &Scratch) -> std::path::PathBuf {
    let out =
        ferrobus().args(["completions", "bash", "--completer", env!("CARGO_BIN_EXE_ferrobus")]).assert().success();
    dir.file("ferrobus.bash", &stdout(&out))
}

/// What bash offers at a Tab after `words` (the last one is the word being completed).
fn tab(dir: &Scratch, words: &[&str]) -> Vec<String> {
    let script = bash_script(dir);
    let quoted: Vec<String> = words.iter().map(|w| format!("'{w}'")).collect();
    let program = format!(
        "source '{}'; COMP_WORDS=({}); COMP_CWORD={}; COMP_TYPE=9; \
         _clap_complete_ferrobus ferrobus '{}' '{}'; printf '%s\\n' \"${{COMPREPLY[@]}}\"",
        script.display(),
        quoted.join(" "),
        words.len() - 1,
        words[words.len() - 1],
        words[words.len() - 2],
    );
    let out = Command::new("bash").arg("-c").arg(program).env("XDG_CONFIG_HOME", &dir.0).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap().lines().map(|l| l.trim_end().to_string()).filter(|l| !l.is_empty()).collect()
}

#[test]
fn bash_sources_the_script_and_complete_p_shows_ferrobus() {
    if !required("bash") {
        return;
    }
    let dir = Scratch::new("complete-p");
    let script = bash_script(&dir);
    let out = Command::new("bash")
        .arg("-c")
        .arg(format!("source '{}' && complete -p ferrobus", script.display()))
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let shown = String::from_utf8(out.stdout).unwrap();
    assert!(shown.contains("-F _clap_complete_ferrobus ferrobus"), "{shown}");
}

#[test]
fn bash_completes_commands_saved_connections_and_built_in_profiles() {
    if !required("bash") {
        return;
    }
    let dir = Scratch::new("complete-tab");
    dir.file("ferrobus/config.toml", "[connection.line-a]\nport = \"/dev/ttyUSB0\"\n[connection.plc]\ntcp = \"plc\"\n");
    assert!(tab(&dir, &["ferrobus", "po"]).contains(&"ports".to_string()));
    assert_eq!(tab(&dir, &["ferrobus", "--conn", ""]), ["line-a", "plc"]);
    assert_eq!(tab(&dir, &["ferrobus", "read", "--conn", "p"]), ["plc"]);
    assert_eq!(tab(&dir, &["ferrobus", "--device", "omr"]), ["omron-3g3rx"]);
    assert_eq!(tab(&dir, &["ferrobus", "--parity", "o"]), ["odd"]);
}

#[test]
fn zsh_registers_the_completer_and_gets_saved_connections_through_it() {
    if !required("zsh") {
        return;
    }
    let dir = Scratch::new("complete-zsh");
    let out = ferrobus().args(["completions", "zsh", "--completer", env!("CARGO_BIN_EXE_ferrobus")]).assert().success();
    let script = dir.file("_ferrobus", &stdout(&out));
    let program = format!(
        "autoload -Uz compinit && compinit -u -d '{}' && source '{}' && print -r -- ${{_comps[ferrobus]}}",
        dir.0.join("zcompdump").display(),
        script.display()
    );
    let out = Command::new("zsh").arg("-fc").arg(program).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8(out.stdout).unwrap(), "_clap_dynamic_completer_ferrobus\n");
    // What the script's function asks at a Tab after `ferrobus --conn l`.
    dir.file("ferrobus/config.toml", "[connection.line-a]\nport = \"/dev/ttyUSB0\"\n[connection.plc]\ntcp = \"plc\"\n");
    let out = ferrobus()
        .env("XDG_CONFIG_HOME", &dir.0)
        .env("FERROBUS_COMPLETE", "zsh")
        .env("_CLAP_COMPLETE_INDEX", "2")
        .env("_CLAP_IFS", "\n")
        .args(["--", "ferrobus", "--conn", "l"])
        .assert()
        .success();
    assert_eq!(stdout(&out), "line-a");
}

#[test]
fn every_shell_gets_a_script_that_asks_ferrobus_at_each_tab() {
    for (shell, marker) in [
        ("bash", "complete -o"),
        ("zsh", "compdef"),
        ("fish", "complete --keep-order --exclusive --command ferrobus"),
        ("powershell", "Register-ArgumentCompleter"),
        ("elvish", "edit:completion:arg-completer[ferrobus]"),
    ] {
        let text = stdout(&ferrobus().args(["completions", shell]).assert().success());
        assert!(text.contains(marker), "{shell}: {marker} in {text}");
        assert!(text.contains("FERROBUS_COMPLETE"), "{shell}: {text}");
    }
    let out = ferrobus().args(["completions", "tcsh"]).assert().code(2);
    assert!(stderr(&out).contains("invalid value 'tcsh'"), "{}", stderr(&out));
}

/// `man -l PAGE`'s warnings (groff's, with man-db's --warnings) and its text.
fn render(page: &std::path::Path) -> (String, String) {
    let out = Command::new("man")
        .args(["--warnings", "-l"])
        .arg(page)
        .env("MANWIDTH", "80")
        .env("MAN_KEEP_FORMATTING", "0")
        .output()
        .unwrap();
    assert!(out.status.success(), "man -l {}: {}", page.display(), String::from_utf8_lossy(&out.stderr));
    // Without a terminal man-db still overstrikes bold (N\bN): keep the letters.
    let mut text = String::new();
    for c in String::from_utf8_lossy(&out.stdout).chars() {
        if c == '\u{8}' {
            text.pop();
        } else {
            text.push(c);
        }
    }
    (String::from_utf8_lossy(&out.stderr).into_owned(), text)
}

#[test]
fn the_man_page_renders_without_warnings_and_names_the_commands() {
    if !required("man") {
        return;
    }
    let dir = Scratch::new("man-page");
    let page = dir.file("ferrobus.1", &stdout(&ferrobus().arg("man").assert().success()));
    let (warnings, text) = render(&page);
    assert_eq!(warnings, "");
    let words: Vec<&str> = text.split_whitespace().collect();
    assert!(words.windows(4).any(|w| w == ["ferrobus", "-", "Modbus", "toolkit"]), "{text}");
    for command in ["read", "ports", "config", "completions", "man"] {
        assert!(text.lines().any(|l| l.trim_start().starts_with(&format!("ferrobus-{command}("))), "{command}: {text}");
    }
    assert!(text.contains("--conn <NAME>"), "{text}");
}

#[test]
fn man_dir_writes_a_page_per_command_each_without_warnings() {
    if !required("man") {
        return;
    }
    let dir = Scratch::new("man-dir");
    let out_dir = dir.0.join("man1");
    ferrobus().args(["man", "--dir", out_dir.to_str().unwrap()]).assert().success();
    let mut pages: Vec<String> =
        std::fs::read_dir(&out_dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    pages.sort();
    for page in ["ferrobus.1", "ferrobus-read.1", "ferrobus-config-show.1", "ferrobus-diag-echo.1", "ferrobus-ports.1"]
    {
        assert!(pages.contains(&page.to_string()), "{page} in {pages:?}");
    }
    for page in &pages {
        let (warnings, _) = render(&out_dir.join(page));
        assert_eq!(warnings, "", "{page}");
    }
}
