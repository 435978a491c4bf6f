#!/usr/bin/env bash
# Bounded smoke run of every cargo-fuzz target in fuzz/.
#
#   FUZZ_SECONDS=20 .ci/fuzz-smoke.sh          # every target for 20 s (the default)
#   FUZZ_SECONDS=60 .ci/fuzz-smoke.sh rtu_receiver slave_engine
#
# Runs on the stable toolchain with `--sanitizer none` (ASan needs nightly, or RUSTC_BOOTSTRAP=1
# and FUZZ_SANITIZER=address). Debug assertions and overflow checks are on. Installs cargo-fuzz
# if it is missing. Prints the executions reached per target; exits non-zero if any target
# crashes, hangs (-timeout), or fails to build. Crash inputs land in fuzz/artifacts/<target>/;
# reproduce one with `cargo fuzz run --sanitizer none -a <target> <file>` in fuzz/.
#
# Honours CARGO_TARGET_DIR. A corpus kept in fuzz/corpus/<target>/ (not committed) is reused.
set -euo pipefail

seconds="${FUZZ_SECONDS:-20}"
sanitizer="${FUZZ_SANITIZER:-none}"
# A single input taking this long counts as a hang.
unit_timeout="${FUZZ_UNIT_TIMEOUT:-10}"

case "$seconds" in
'' | *[!0-9]*)
    echo "FUZZ_SECONDS must be a whole number of seconds, got '$seconds'" >&2
    exit 2
    ;;
esac

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root/fuzz"

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "--- installing cargo-fuzz"
    cargo install cargo-fuzz --locked
fi

if [ "$#" -gt 0 ]; then
    targets=("$@")
else
    mapfile -t targets < <(cargo fuzz list)
fi
if [ "${#targets[@]}" -eq 0 ]; then
    echo "no fuzz targets found in $root/fuzz" >&2
    exit 2
fi

echo "--- building ${#targets[@]} targets (sanitizer: $sanitizer)"
cargo fuzz build --sanitizer "$sanitizer" --debug-assertions

logdir="$(mktemp -d)"
trap 'rm -rf "$logdir"' EXIT
failed=()
summary=()
for target in "${targets[@]}"; do
    echo "--- $target: ${seconds}s"
    log="$logdir/$target.log"
    status=ok
    if ! cargo fuzz run --sanitizer "$sanitizer" --debug-assertions "$target" -- \
        -max_total_time="$seconds" -timeout="$unit_timeout" -print_final_stats=1 >"$log" 2>&1; then
        status=FAILED
    fi
    # A crash input is written even when the exit status says otherwise.
    if grep -qE 'Test unit written to|ERROR: libFuzzer' "$log"; then
        status=FAILED
    fi
    execs="$(sed -n 's/^stat::number_of_executed_units: *\([0-9]*\).*/\1/p' "$log" | tail -n 1)"
    if [ -z "$execs" ]; then
        execs="$(sed -n 's/^#\([0-9]*\)[[:space:]]*DONE.*/\1/p' "$log" | tail -n 1)"
    fi
    execs="${execs:-?}"
    if [ "$status" != ok ]; then
        failed+=("$target")
        echo "$target FAILED; end of its log:"
        tail -n 60 "$log"
    fi
    line="$(printf '%-24s %-7s %12s executions' "$target" "$status" "$execs")"
    summary+=("$line")
    echo "$line"
done

echo "--- summary (${seconds}s per target)"
printf '%s\n' "${summary[@]}"
if [ "${#failed[@]}" -gt 0 ]; then
    echo "crashed or failed: ${failed[*]}" >&2
    exit 1
fi
