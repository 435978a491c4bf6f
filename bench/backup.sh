#!/usr/bin/env bash
# A full parameter backup of a simulated drive over a paced virtual RS-485 line: the
# transactions it used against the read planner's optimum, and its time against the wire
# time of that plan.
#
#   ferrobus line (19200 8E1, real character timing) <-> ferrobus sim --profile PROFILE
#                                                    <-> ferrobus --device PROFILE backup -v
#
# The backup logs each read request (-v) and prints its summary: parameters, requests sent,
# the plan's request count (the planner is proven optimal by ferrobus-profile's tests), and
# the time from its first request to its last reply. The wire time of the plan is, over its
# requests, the request's and the response's characters (11 bits each at 8E1), the t3.5 the
# slave keeps before answering, the device's response wait, and the t3.5 the master keeps
# before each following request.
#
# Usage: bench/backup.sh            (REPS runs, default 5; results on stdout as a table)
# Environment:
#   FERROBUS=PATH    the ferrobus binary (default: cargo build --release -p ferrobus-cli)
#   PROFILE=NAME     the drive: a built-in profile or a profile file (default omron-3g3rx)
#   BAUD=N           the line's baud rate (default 19200); the parity is even
#   REPS=N           runs (default 5)
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
PROFILE="${PROFILE:-omron-3g3rx}"
BAUD="${BAUD:-19200}"
REPS="${REPS:-5}"
WORK="$(mktemp -d)"
PIDS=()

cleanup() {
    local pid
    for pid in "${PIDS[@]}"; do
        kill -TERM "$pid" 2>/dev/null || true
    done
    for pid in "${PIDS[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    rm -rf "$WORK"
}
trap cleanup EXIT INT TERM

die() {
    echo "backup.sh: $*" >&2
    exit 1
}

if [ -z "${FERROBUS:-}" ]; then
    (cd "$ROOT" && cargo build --release -q -p ferrobus-cli) || die "cargo build failed"
    FERROBUS="$ROOT/target/release/ferrobus"
fi
[ -x "$FERROBUS" ] || die "no ferrobus binary at $FERROBUS"

# wait_for FILE PATTERN SECONDS: until FILE holds a line matching PATTERN.
wait_for() {
    local deadline=$((SECONDS + $3))
    until grep -q "$2" "$1" 2>/dev/null; do
        [ "$SECONDS" -lt "$deadline" ] || die "timed out waiting for '$2' in $1"
        sleep 0.05
    done
}

for rep in $(seq 1 "$REPS"); do
    : >"$WORK/line.out"
    "$FERROBUS" line --drops 2 --baud "$BAUD" --parity even >"$WORK/line.out" 2>"$WORK/line.err" &
    line_pid=$!
    PIDS+=("$line_pid")
    wait_for "$WORK/line.out" '^/' 10
    sleep 0.1
    a="$(sed -n 1p "$WORK/line.out")"
    b="$(sed -n 2p "$WORK/line.out")"
    "$FERROBUS" --port "$a" --baud "$BAUD" --parity even sim --profile "$PROFILE" >/dev/null 2>"$WORK/sim.err" &
    sim_pid=$!
    PIDS+=("$sim_pid")
    wait_for "$WORK/sim.err" 'sim: serving on' 20
    "$FERROBUS" -v --port "$b" --baud "$BAUD" --parity even --timeout 2s --device "$PROFILE" \
        backup -o "$WORK/backup.toml" 2>"$WORK/backup.err" || die "the backup failed: $(cat "$WORK/backup.err")"
    # The control: ferrobus bench, FC03 back to back on the same line, the plan's first
    # holding request's shape; its time against its wire time is what the line and the
    # machine cost any client.
    shape="$(grep -o 'read request table="holding" start=[0-9]* count=[0-9]*' "$WORK/backup.err" | head -1)"
    start="$(echo "$shape" | sed 's/.*start=\([0-9]*\).*/\1/')"
    count="$(echo "$shape" | sed 's/.*count=\([0-9]*\).*/\1/')"
    "$FERROBUS" --port "$b" --baud "$BAUD" --parity even --timeout 2s bench --count 20 --address "$start" \
        --quantity "$count" --json >"$WORK/bench-$rep.json" 2>"$WORK/bench.err" || die "bench failed: $(cat "$WORK/bench.err")"
    echo "$count" >"$WORK/bench-$rep.count"
    kill -TERM "$sim_pid" "$line_pid" 2>/dev/null || true
    wait "$sim_pid" "$line_pid" 2>/dev/null || true
    PIDS=()
    cp "$WORK/backup.err" "$WORK/run-$rep.err"
    cp "$WORK/sim.err" "$WORK/sim-$rep.err"
done

python3 - "$WORK" "$REPS" "$BAUD" "$PROFILE" "$ROOT" <<'EOF'
import json, os, re, statistics, sys, tomllib
work, reps, baud, profile, root = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4], sys.argv[5]
char = 11 / baud                                  # 8E1: start, 8 data, parity, stop
t35 = 3.5 * char if baud <= 19200 else 1.75e-3    # the spec fixes 1.75 ms above 19200
path = profile if os.path.isfile(profile) else f"{root}/crates/ferrobus-profile/profiles/{profile}.toml"
try:
    with open(path, "rb") as f:
        wait = tomllib.load(f).get("comm", {}).get("response_wait_ms", 0) / 1e3
except FileNotFoundError:
    wait = 0.0
runs = []
for rep in range(1, reps + 1):
    text = open(f"{work}/run-{rep}.err").read()
    requests = re.findall(r'read request table="(\w+)" start=(\d+) count=(\d+)', text)
    m = re.search(r"backup: (\d+) of (\d+) parameters of unit \d+ in (\d+) requests \(the plan's (\d+)\), ([\d.]+) ms", text)
    if not m:
        sys.exit(f"backup.sh: no summary in run {rep}:\n{text}")
    saved, total, used, planned, ms = int(m[1]), int(m[2]), int(m[3]), int(m[4]), float(m[5])
    wire = 0.0
    for table, start, count in requests:
        n = int(count)
        resp = 5 + (2 * n if table in ("holding", "input") else (n + 7) // 8)
        wire += (8 + resp) * char + t35 + wait
    wire += t35 * max(len(requests) - 1, 0)
    late = re.search(r"p50 (\d+) µs", open(f"{work}/sim-{rep}.err").read())
    bench = json.load(open(f"{work}/bench-{rep}.json"))
    q = int(open(f"{work}/bench-{rep}.count").read())
    bench_wire = bench["transactions"] * ((8 + 5 + 2 * q) * char + 2 * t35 + wait)
    bench_ratio = bench["seconds"] / bench_wire
    runs.append(dict(saved=saved, total=total, used=used, planned=planned, ms=ms, wire_ms=wire * 1e3,
                     sim_late_p50_us=int(late[1]) if late else None, bench_ratio=bench_ratio))
med = lambda k: statistics.median(r[k] for r in runs)
print(f"profile {profile}, {baud} 8E1, {reps} runs; character {char*1e6:.1f} µs, t3.5 {t35*1e6:.1f} µs, response wait {wait*1e3:.0f} ms")
print()
print("| run | parameters | requests used | plan's (optimum) | time | wire time of the plan | time / wire | control: bench time / wire | sim reply late p50 |")
print("|---|---|---|---|---|---|---|---|---|")
for i, r in enumerate(runs, 1):
    print(f"| {i} | {r['saved']}/{r['total']} | {r['used']} | {r['planned']} | {r['ms']:.1f} ms | {r['wire_ms']:.1f} ms | "
          f"{r['ms']/r['wire_ms']:.3f} | {r['bench_ratio']:.3f} | {r['sim_late_p50_us']} µs |")
ratio = statistics.median(r["ms"] / r["wire_ms"] for r in runs)
print(f"| median | | {med('used'):g} | {med('planned'):g} | {med('ms'):.1f} ms | {med('wire_ms'):.1f} ms | {ratio:.3f} | {med('bench_ratio'):.3f} | |")
print()
ok_count = all(r["used"] == r["planned"] for r in runs)
print(f"transactions: {'equal to' if ok_count else 'NOT equal to'} the optimum in every run (goal: equal)")
print(f"time: median {100*(ratio-1):+.1f} % against the wire time (goal: within 5 %); "
      f"the control (ferrobus bench on the same line): {100*(med('bench_ratio')-1):+.1f} %")
EOF
