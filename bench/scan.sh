#!/usr/bin/env bash
# bench/scan.sh - how close a full `ferrobus scan` sweep comes to its theoretical minimum.
#
# One setting, 19200 8E1, units 1-247, the default probe (FC03 address 0 count 1) and the
# default probe timeout, on `ferrobus line` (a virtual RS-485 line with real character timing)
# where no device answers: every probe waits its whole timeout. The minimum is
#
#   247 x (request wire time + t3.5 + timeout)
#   timeout = first-byte wait (100 ms) + the expected reply's wire time (7 characters)
#
# i.e. 247 x (8 + 3.5 + 7 characters of 11 bits at 19200 baud + 100 ms) = 27.318 s. The goal is a
# sweep within 5 % of it. The script also prints the tighter bound 247 x (request wire time +
# timeout): after a silent probe the line has been quiet for the whole timeout, so the t3.5
# before the next request is already over and costs nothing. --listen 0: listening first adds
# its own duration per setting, by design.
#
# Environment:
#   FERROBUS=PATH  the ferrobus binary (default: cargo build -p ferrobus-cli, then
#                  $CARGO_TARGET_DIR or target/debug/ferrobus; the sweep is waits, not CPU)
#   REPS=N         sweeps (default 3); the median is reported
#   UNITS=RANGE    units (default 1-247)
# Prints one line per sweep and the median with its ratio to the minimum. Record the result in
# bench/SCAN.md by hand.
set -euo pipefail

here=$(cd "$(dirname "$0")" && pwd)
reps=${REPS:-3}
units=${UNITS:-1-247}
if [[ -z "${FERROBUS:-}" ]]; then
    (cd "$here/.." && cargo build -q -p ferrobus-cli)
    FERROBUS="${CARGO_TARGET_DIR:-$here/../target}/debug/ferrobus"
fi
work=$(mktemp -d)
line_pid=
cleanup() {
    [[ -n "$line_pid" ]] && kill "$line_pid" 2>/dev/null && wait "$line_pid" 2>/dev/null
    rm -rf "$work"
}
trap cleanup EXIT

"$FERROBUS" --baud 19200 line --drops 2 >"$work/drops" 2>"$work/line.err" &
line_pid=$!
for _ in $(seq 100); do
    [[ $(wc -l <"$work/drops") -ge 2 ]] && break
    sleep 0.1
done
port=$(head -1 "$work/drops")

for rep in $(seq "$reps"); do
    "$FERROBUS" --port "$port" scan --units "$units" --bauds 19200 --framings 8E1 --listen 0 --json \
        >"$work/scan-$rep.json"
done

python3 - "$work" "$reps" <<'PY'
import json, statistics, sys
work, reps = sys.argv[1], int(sys.argv[2])
char = 11 / 19200
docs = [json.load(open(f"{work}/scan-{i}.json")) for i in range(1, reps + 1)]
for d in docs:
    assert d["complete"] and not d["devices"], d
probes = docs[0]["probes"]
minimum = probes * ((8 + 3.5 + 7) * char + 0.100)
times = [d["seconds"] for d in docs]
for i, t in enumerate(times, 1):
    print(f"sweep {i}: {probes} probes in {t:.3f} s ({t / minimum:.4f} x the minimum)")
med = statistics.median(times)
print(f"median {med:.3f} s; minimum {minimum:.3f} s ({probes} x {minimum / probes * 1000:.3f} ms); "
      f"ratio {med / minimum:.4f} ({(med / minimum - 1) * 100:+.2f} %, goal < +5 %); "
      f"{(med - minimum) / probes * 1e6:.0f} us over the minimum per probe")
tight = probes * ((8 + 7) * char + 0.100)
print(f"tighter bound without t3.5 (it overlaps the timeout's silence): {tight:.3f} s; ratio {med / tight:.4f} "
      f"({(med / tight - 1) * 100:+.2f} %); {(med - tight) / probes * 1e6:.0f} us per probe over it")
PY
