#!/usr/bin/env bash
# The whole test suite: what CI runs (.ci/run calls exactly this), and what to run before a
# push. Installs what the tests need (apt and pip packages for the peer stacks, the bare-metal
# Rust target, cargo-fuzz), then runs, stopping at the first failure:
#
#   format   cargo fmt --check
#   lint     cargo clippy --workspace --all-targets -D warnings, for Linux, Windows
#            (x86_64-pc-windows-gnu) and macOS (x86_64-apple-darwin)
#   tests    cargo test --workspace: unit, property, engine, line, simulator, CLI, and the
#            interop tests against libmodbus, pymodbus, tokio-modbus and mbpoll
#            (also the Debian package: scripts/deb.sh, dpkg -x, the unpacked ferrobus run)
#   no_std   ferrobus-proto built for a Cortex-M (thumbv7em-none-eabihf)
#   docs     cargo doc with warnings denied (every public item documented, links resolve)
#   windows  the Windows build under wine: proto, simulator and IO unit tests, and ferrobus.exe
#            against a Linux `ferrobus sim --tcp` (.ci/windows-wine.sh)
#   fuzz     every cargo-fuzz target for FUZZ_SECONDS (default 20) each
#
# Under CI=true a missing peer stack is a failure, never a skip.
#
#   scripts/test.sh                # everything
#   SKIP_FUZZ=1 scripts/test.sh    # everything but the fuzz smoke run
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"

# Each step says how much disk is left: a full disk shows as a linker's bus error.
step() {
    printf '\n=== %s (%s free)\n' "$*" "$(df -Pk . | awk 'NR == 2 { printf "%.1f GiB", $4 / 1048576 }')"
}

if [ -n "${CI:-}" ]; then
    # A fresh clone builds once: an incremental cache would only take disk.
    export CARGO_INCREMENTAL=0
fi

started=$SECONDS

step "setup: peer stacks (libmodbus, pymodbus, tokio-modbus, mbpoll, socat)"
.ci/setup-peers.sh

step "setup: Rust components"
rustup component add rustfmt clippy >/dev/null 2>&1 || true
rustup target add thumbv7em-none-eabihf

step "setup: cross targets (mingw-w64, wine, clang; Windows and macOS Rust targets)"
.ci/setup-cross.sh

step "format"
cargo fmt --all -- --check

step "lint"
cargo clippy --workspace --all-targets --locked -- -D warnings

step "lint: Windows (x86_64-pc-windows-gnu)"
cargo clippy --workspace --all-targets --locked --target x86_64-pc-windows-gnu -- -D warnings

step "lint: macOS (x86_64-apple-darwin)"
# No SDK here: the C that crates build is compiled by clang, freestanding (.ci/darwin-env.sh);
# a check links nothing.
(
    source .ci/darwin-env.sh
    cargo clippy --workspace --all-targets --locked --target x86_64-apple-darwin -- -D warnings
)

step "tests"
cargo test --workspace --locked

step "no_std: ferrobus-proto for a Cortex-M, without std or alloc"
cargo build -p ferrobus-proto --target thumbv7em-none-eabihf --locked

step "docs"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --locked

step "windows: the Windows build under wine"
.ci/windows-wine.sh

if [ -z "${SKIP_FUZZ:-}" ]; then
    step "fuzz smoke run"
    FUZZ_SECONDS="${FUZZ_SECONDS:-20}" .ci/fuzz-smoke.sh
fi

step "all passed in $((SECONDS - started)) s"
