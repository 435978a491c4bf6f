#!/usr/bin/env bash
# .ci/windows-wine.sh - the Windows build, run under wine (needs .ci/setup-cross.sh).
#
#   1. cargo test for x86_64-pc-windows-gnu of ferrobus-proto, ferrobus-sim and ferrobus's
#      own unit tests, each executable run by tests/wine/run.sh (wine64, a private prefix,
#      the bcryptprimitives.dll stand-in of tests/wine/ that wine 8 lacks);
#   2. the Windows `ferrobus.exe` writing, reading and benchmarking a Linux `ferrobus sim --tcp`,
#      and running the demo (its virtual line in-process).
#
# The runs under wine are bounded: WINE_SECONDS (default 180) for the tests, a minute for the
# CLI; they share one persistent wineserver, stopped at the end. Honours CARGO_TARGET_DIR,
# WINE (the wine binary) and WINESERVER.
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
target_dir="${CARGO_TARGET_DIR:-$root/target}"
seconds="${WINE_SECONDS:-180}"
export CARGO_TARGET_X86_64_PC_WINDOWS_GNU_RUNNER="$root/tests/wine/run.sh"
export WINEPREFIX="${WINEPREFIX:-$target_dir/wine/prefix}"
export WINEDEBUG="${WINEDEBUG:--all}"
wineserver="${WINESERVER:-/usr/lib/wine/wineserver}"
sim=""
# Stops the simulator, if started, and the wineserver.
cleanup() {
    if [ -n "$sim" ]; then
        kill "$sim" 2>/dev/null || true
        wait "$sim" 2>/dev/null || true
    fi
    "$wineserver" -k 2>/dev/null || true
}
trap cleanup EXIT

echo "--- building the Windows tests and binary"
cargo build --locked --target x86_64-pc-windows-gnu -p ferrobus-cli --bin ferrobus
cargo test --locked --target x86_64-pc-windows-gnu -p ferrobus-proto -p ferrobus-sim -p ferrobus -p ferrobus-tools --lib --tests --no-run

echo "--- the wine prefix, and one wineserver for the whole step"
# A wineserver that exits once its last program has (after a few seconds) drops a program
# that starts just then ("wine client error:0: recvmsg: Connection reset by peer"), and the
# tests start one program after another: this one is persistent (-p) until the end of the
# step. The prefix is made here, not by the first test program.
mkdir -p "$WINEPREFIX"
"$wineserver" -p
timeout --kill-after=10 120 "${WINE:-/usr/lib/wine/wine64}" wineboot --init

echo "--- under wine: ferrobus-proto, ferrobus-sim, ferrobus and ferrobus-tools (lib) tests (at most ${seconds}s)"
timeout --kill-after=10 "$seconds" \
    cargo test --locked --target x86_64-pc-windows-gnu -p ferrobus-proto -p ferrobus-sim --lib --tests
timeout --kill-after=10 "$seconds" \
    cargo test --locked --target x86_64-pc-windows-gnu -p ferrobus -p ferrobus-tools --lib

echo "--- under wine: ferrobus.exe against a Linux ferrobus sim --tcp"
cargo build --locked -p ferrobus-cli --bin ferrobus
port=$((20000 + RANDOM % 20000))
log="$(mktemp)"
"$target_dir/debug/ferrobus" sim --profile generic --unit 1 --tcp "127.0.0.1:$port" --duration 90s 2>"$log" &
sim=$!
trap 'cleanup; rm -f "$log"' EXIT
for _ in $(seq 50); do
    grep -q 'listening on' "$log" && break
    sleep 0.1
done
exe="$target_dir/x86_64-pc-windows-gnu/debug/ferrobus.exe"
win() { timeout --kill-after=10 60 tests/wine/run.sh "$exe" --tcp "127.0.0.1:$port" --unit 1 "$@"; }
check() { # check WHAT EXPECTED OUTPUT
    if ! grep -qw "$2" <<<"$3"; then
        echo "ferrobus.exe: $1: expected $2 in what it printed: '$3'" >&2
        cat "$log" >&2
        exit 1
    fi
    echo "$1: $3"
}
win write register 0x0010 4660
check "FC06 then FC03" 4660 "$(win read holding 0x0010 --csv)"
win write register --type u32 0x0020 305419896
check "FC10 then FC03, u32" 305419896 "$(win read holding --type u32 0x0020 --csv)"
bench="$(win bench --count 200 --json)"
check "bench, 200 FC03 reads" '"errors":0' "$bench"
echo "--- the Windows binary wrote, read and benchmarked the Linux simulator"

echo "--- under wine: ferrobus.exe demo (its virtual line in-process, no pty)"
demo="$(timeout --kill-after=10 60 tests/wine/run.sh "$exe" demo)"
check "demo, the loop-back test" "echoed 0x12 0x34" "$(grep -m1 echoed <<<"$demo")"
check "demo, the drive ramps" "running" "$(grep -m1 running <<<"$demo")"

echo "--- under wine: ferrobus.exe ports (SetupAPI through serialport; wine lists the COM ports it maps)"
ports="$(timeout --kill-after=10 60 tests/wine/run.sh "$exe" ports --json)"
check "ports --json" '"ports"' "$ports"
