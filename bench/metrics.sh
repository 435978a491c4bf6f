#!/usr/bin/env bash
# bench/metrics.sh - what `--metrics` costs the gateway: its throughput and CPU per transaction
# with the status endpoint scraped every second, against the same gateway without it.
#
#   ferrobus sim --profile generic --tcp  <──  ferrobus gateway --tcp SIM --listen L [--metrics M]
#        <──  bench/gateway_load.py: 10 closed-loop Modbus/TCP clients, FC03 x 10
#        <──  with --metrics: curl of /metrics and /status.json every second (Prometheus's
#             rate, and a status page left open)
#
# The device is a simulator over TCP, not a paced serial line, so that the gateway itself is
# the bottleneck and what the endpoint costs shows in its CPU. Runs alternate off/on, on/off
# (ABBA) over PAIRS pairs so that the machine's drift falls on both; each run is a fresh
# gateway. Prints one JSON record per run, then the medians and the difference.
#
# Environment: FERROBUS=PATH (default target/release/ferrobus), PYTHON (python3),
# SECONDS_PER_RUN (default 10), PAIRS (default 5), CLIENTS (default 10).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FERROBUS="${FERROBUS:-$ROOT/target/release/ferrobus}"
PYTHON="${PYTHON:-python3}"
RUN="${SECONDS_PER_RUN:-10}"
PAIRS="${PAIRS:-5}"
CLIENTS="${CLIENTS:-10}"
[ -x "$FERROBUS" ] || { echo "metrics.sh: $FERROBUS is missing: cargo build --release -p ferrobus-cli" >&2; exit 1; }
command -v curl >/dev/null || { echo "metrics.sh: curl is missing (apt install curl)" >&2; exit 1; }
WORK="$(mktemp -d)"
PIDS=()
cleanup() {
    for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
    rm -rf "$WORK"
}
trap cleanup EXIT
log() { printf 'metrics.sh: %s\n' "$*" >&2; }
free_port() { "$PYTHON" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
wait_for() { # wait_for FILE TEXT
    for _ in $(seq 1 500); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.02; done
    echo "metrics.sh: no '$2' in $1:" >&2
    cat "$1" >&2
    exit 1
}
stop() { kill -TERM "$1" 2>/dev/null || true; wait "$1" 2>/dev/null || true; }

SIM_PORT="$(free_port)"
"$FERROBUS" sim --profile generic --tcp "127.0.0.1:$SIM_PORT" 2>"$WORK/sim.err" &
PIDS+=("$!")
wait_for "$WORK/sim.err" "sim: listening on"

# run MODE (off|on): one gateway, one load; prints its record.
run() {
    local mode="$1" listen metrics=() scraper=""
    listen="$(free_port)"
    if [ "$mode" = on ]; then
        local at="127.0.0.1:$(free_port)"
        metrics=(--metrics "$at")
    fi
    "$FERROBUS" --tcp "127.0.0.1:$SIM_PORT" gateway --listen "127.0.0.1:$listen" "${metrics[@]}" 2>"$WORK/gw.err" &
    local gw=$!
    PIDS+=("$gw")
    wait_for "$WORK/gw.err" "gateway: listening on"
    if [ "$mode" = on ]; then
        (while curl -sf "http://${metrics[1]}/metrics" >/dev/null && curl -sf "http://${metrics[1]}/status.json" >/dev/null; do
            sleep 1
        done) &
        scraper=$!
        PIDS+=("$scraper")
    fi
    local load
    load="$("$PYTHON" "$ROOT/bench/gateway_load.py" --addr "127.0.0.1:$listen" --clients "$CLIENTS" \
        --seconds "$RUN" --warmup 1 --cpu "gateway=$gw")"
    [ -n "$scraper" ] && stop "$scraper"
    stop "$gw"
    printf '{"metrics":"%s","load":%s}\n' "$mode" "$load"
}

# scrape_cost N: the gateway's CPU per scrape (/metrics and /status.json), N scrapes of an idle
# gateway that has served a load first (its counters and histograms full): CPU time is the
# process's own, so this figure holds on a busy machine where throughput does not.
scrape_cost() {
    local n="$1" listen at ticks0 ticks1
    listen="$(free_port)"
    at="127.0.0.1:$(free_port)"
    "$FERROBUS" --tcp "127.0.0.1:$SIM_PORT" gateway --listen "127.0.0.1:$listen" --metrics "$at" 2>"$WORK/gw.err" &
    local gw=$!
    PIDS+=("$gw")
    wait_for "$WORK/gw.err" "gateway: listening on"
    "$PYTHON" "$ROOT/bench/gateway_load.py" --addr "127.0.0.1:$listen" --clients "$CLIENTS" --seconds 2 >/dev/null
    ticks0="$(awk '{print $14 + $15}' "/proc/$gw/stat")"
    for _ in $(seq "$n"); do
        curl -sf "http://$at/metrics" >/dev/null
        curl -sf "http://$at/status.json" >/dev/null
    done
    ticks1="$(awk '{print $14 + $15}' "/proc/$gw/stat")"
    stop "$gw"
    awk -v n="$n" -v a="$ticks0" -v b="$ticks1" -v hz="$(getconf CLK_TCK)" \
        'BEGIN { printf "{\"scrapes\":%d,\"cpu_us_per_scrape\":%.1f}\n", n, (b - a) * 1e6 / hz / n }'
}

log "machine: $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg); $("$FERROBUS" --version); $PAIRS pairs of ${RUN} s, $CLIENTS clients"
records="$WORK/records.jsonl"
for pair in $(seq 1 "$PAIRS"); do
    if [ $((pair % 2)) = 1 ]; then order="off on"; else order="on off"; fi
    for mode in $order; do run "$mode" | tee -a "$records"; done
done
scrape_cost 1000 | tee "$WORK/scrape.json"
"$PYTHON" - "$records" "$WORK/scrape.json" <<'PY'
import json, statistics, sys
runs = [json.loads(l) for l in open(sys.argv[1])]
scrape = json.load(open(sys.argv[2]))
def figures(mode):
    tps = [r["load"]["tps"] for r in runs if r["metrics"] == mode]
    cpu = [r["load"]["cpu"]["gateway"]["us_per_transaction"] for r in runs if r["metrics"] == mode]
    p50 = [r["load"]["p50_ms"] for r in runs if r["metrics"] == mode]
    wrong = sum(r["load"]["mismatches"] + r["load"]["lost"] for r in runs if r["metrics"] == mode)
    return statistics.median(tps), statistics.median(cpu), len(tps), statistics.median(p50), wrong
off, on = figures("off"), figures("on")
print("| --metrics | runs | transactions/s (median) | gateway CPU µs/tx (median) | p50 ms (median) | mismatches + lost |")
print("|---|---:|---:|---:|---:|---:|")
for name, (tps, cpu, n, p50, wrong) in (("off", off), ("on, scraped every 1 s", on)):
    print(f"| {name} | {n} | {tps:.0f} | {cpu:.2f} | {p50:.2f} | {wrong} |")
print(f"throughput on/off: {on[0] / off[0]:.4f} ({(on[0] / off[0] - 1) * 100:+.2f} %); "
      f"CPU per transaction on/off: {on[1] / off[1]:.4f} ({(on[1] / off[1] - 1) * 100:+.2f} %)")
# One scrape a second against the gateway's CPU per second when it runs flat out.
busy = off[1] * off[0] / 1e6
print(f"one scrape (/metrics and /status.json): {scrape['cpu_us_per_scrape']:.0f} µs of the gateway's CPU "
      f"({scrape['scrapes']} scrapes); once a second that is {scrape['cpu_us_per_scrape'] / 1e6 / busy * 100:.3f} % "
      f"of the {busy * 100:.0f} % of a core the gateway spends at {off[0]:.0f} transactions/s")
PY
