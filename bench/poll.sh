#!/usr/bin/env bash
# `ferrobus poll` at 100 points a second for a while: CPU per poll, RSS growth, rate drift.
#
#   ferrobus sim --pty --profile generic  <->  ferrobus poll: 10 groups of 10 holding
#                                              registers, each every second, --jsonl
#                                              (100 points/s in 10 polls/s)
#
# The poller's CPU time (utime + stime from /proc) over the run is divided by its polls; its
# RSS is sampled 5 s after the start and at the end; drift is read from the records:
# `late_ms` (start minus deadline, deadlines being start + k × period) of the first group (the
# others wait behind it: all ten are due at the same instant) over the first and the last
# minute, and the wall-clock span of the records against the span of their deadlines.
#
# Usage: bench/poll.sh                 (results on stdout)
# Environment:
#   FERROBUS=PATH    the ferrobus binary (default: target/debug/ferrobus, built if missing)
#   DURATION=SECS    how long to poll (default 600, the issue's 10 minutes)
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DURATION="${DURATION:-600}"
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
trap cleanup EXIT

FERROBUS="${FERROBUS:-$ROOT/target/debug/ferrobus}"
if [[ ! -x "$FERROBUS" ]]; then
    (cd "$ROOT" && cargo build -p ferrobus-cli)
fi

"$FERROBUS" sim --pty --profile generic --duration "$((DURATION + 30))s" >"$WORK/sim.out" 2>"$WORK/sim.err" &
PIDS+=($!)
for _ in $(seq 100); do
    [[ -s "$WORK/sim.out" ]] && break
    sleep 0.05
done
PTY="$(head -1 "$WORK/sim.out")"

SPEC=()
for g in $(seq 0 9); do
    SPEC+=(holding "$((g * 10))" --count 10 --every 1s)
done
"$FERROBUS" --port "$PTY" --parity none --timeout 200ms poll "${SPEC[@]}" --jsonl \
    >"$WORK/records.jsonl" 2>"$WORK/summary.txt" &
POLL=$!
PIDS+=($POLL)

rss() { awk '/^VmRSS/ {print $2}' "/proc/$POLL/status"; }
cpu_ticks() { awk '{print $14 + $15}' "/proc/$POLL/stat"; }

sleep 5
RSS_START="$(rss)"
CPU_START="$(cpu_ticks)"
sleep "$((DURATION - 5))"
RSS_END="$(rss)"
CPU_END="$(cpu_ticks)"
kill -TERM "$POLL"
wait "$POLL" || true

python3 - "$WORK/records.jsonl" "$WORK/summary.txt" "$RSS_START" "$RSS_END" "$CPU_START" "$CPU_END" \
    "$(getconf CLK_TCK)" "$DURATION" <<'PY'
import json, statistics, sys
from datetime import datetime
records_path, summary_path, rss0, rss1, cpu0, cpu1, tck, duration = sys.argv[1:]
records = [json.loads(l) for l in open(records_path)]
summary = open(summary_path).read()
ok = sum(r["status"] == "ok" for r in records)
points = sum(len(r["points"]) for r in records)
def t(r): return datetime.fromisoformat(r["time"].replace("Z", "+00:00")).timestamp()
# Polls between the two CPU samples: those due from 5 s to the end sample.
window = [r for r in records if 5000 <= r["due_ms"]]
cpu_s = (int(cpu1) - int(cpu0)) / int(tck)
late = [r["late_ms"] for r in records if r["group"] == records[0]["group"]]
first, last = late[:60], late[-60:]  # one poll a second
everyone = [r["late_ms"] for r in records]
span_wall = (t(records[-1]) - t(records[0])) * 1e3
span_due = records[-1]["due_ms"] - records[0]["due_ms"]
print(f"run: {duration} s, {len(records)} polls ({ok} ok), {points} points "
      f"= {points / float(duration):.1f} points/s")
print(f"CPU: {cpu_s:.2f} s over {len(window)} polls = {cpu_s / max(len(window), 1) * 1e6:.0f} us per poll")
print(f"RSS: {rss0} kB at 5 s, {rss1} kB at the end ({int(rss1) - int(rss0):+d} kB)")
print(f"late (start - deadline), first group: first minute p50 {statistics.median(first):.3f} ms, "
      f"max {max(first):.3f} ms; last minute p50 {statistics.median(last):.3f} ms, max {max(last):.3f} ms")
print(f"late, every group (waiting behind the others): p50 {statistics.median(everyone):.3f} ms, "
      f"max {max(everyone):.3f} ms")
print(f"drift: the records' wall-clock span {span_wall:.1f} ms against their deadlines' {span_due:.1f} ms "
      f"({span_wall - span_due:+.1f} ms; includes the last poll's response time and ms timestamps)")
print(f"overruns: {sum(r['overrun'] for r in records)}")
print("\n".join(l for l in summary.splitlines() if l.startswith("poll: ") and "polls" in l or "response time" in l))
PY
