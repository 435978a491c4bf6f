#!/usr/bin/env bash
# bench/gateway.sh - `ferrobus gateway` on a paced virtual line (`ferrobus line`, real
# character timing) with `ferrobus sim --profile generic` behind it, FC03 x 10 per request.
#
# At 9600 8E1 and 115200 8N1: 1, 10 and 100 Modbus/TCP clients (bench/gateway_load.py), each
# sending its next request when the last reply arrives: transactions/s as a share of the
# conforming limit (33 characters and two t3.5 per transaction, bench/report.py's
# theoretical_tps) and beside `ferrobus bench` straight on the line (the best a master does on
# this line), fairness max/min per client, p50/p99 round trip, mismatches, lost connections,
# exceptions, and the frames the gateway began less than t3.5 after the line was busy (the
# line's gap_violations). At 115200 also 1,000 clients, and a dead unit among 10 live ones
# (one client polling it, ten polling the live units) against the same ten without it.
#
# Prints one JSON record per run and a table; writes bench/GATEWAY.md's results section only
# by hand (the figures of one run go there with the machine they were measured on).
#
# Environment: FERROBUS=PATH (default target/release/ferrobus), PYTHON (python3),
# SECONDS_PER_RUN (default 15), QUICK=1 (4 s runs, for a smoke test).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FERROBUS="${FERROBUS:-$ROOT/target/release/ferrobus}"
PYTHON="${PYTHON:-python3}"
RUN="${SECONDS_PER_RUN:-15}"
[ "${QUICK:-0}" = 1 ] && RUN=4
[ -x "$FERROBUS" ] || { echo "gateway.sh: $FERROBUS is missing: cargo build --release -p ferrobus-cli" >&2; exit 1; }
ulimit -n 4096
WORK="$(mktemp -d)"
PIDS=()
cleanup() {
    for pid in "${PIDS[@]}"; do kill "$pid" 2>/dev/null || true; done
    rm -rf "$WORK"
}
trap cleanup EXIT
log() { printf 'gateway.sh: %s\n' "$*" >&2; }
wait_for() { # wait_for FILE TEXT
    for _ in $(seq 1 500); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.02; done
    echo "gateway.sh: no '$2' in $1:" >&2
    cat "$1" >&2
    exit 1
}
stop() { kill -"$2" "$1" 2>/dev/null || true; wait "$1" 2>/dev/null || true; }

# start_line BAUD PARITY: a fresh paced line; sets A and B (its two ptys) and LINE_PID.
start_line() {
    rm -f "$WORK/line.json"
    : >"$WORK/line.out"
    "$FERROBUS" line --drops 2 --baud "$1" --parity "$2" --stats-json "$WORK/line.json" >"$WORK/line.out" 2>"$WORK/line.err" &
    LINE_PID=$!
    PIDS+=("$LINE_PID")
    for _ in $(seq 1 500); do [ "$(wc -l <"$WORK/line.out")" -ge 2 ] && break; sleep 0.02; done
    A="$(sed -n 1p "$WORK/line.out")"
    B="$(sed -n 2p "$WORK/line.out")"
}

# start_sim BAUD PARITY UNITS...: the generic sim on A for each unit.
start_sim() {
    local baud="$1" parity="$2" args=()
    shift 2
    for u in "$@"; do args+=(--unit "$u"); done
    "$FERROBUS" --port "$A" --baud "$baud" --parity "$parity" sim --profile generic "${args[@]}" 2>"$WORK/sim.err" &
    SIM_PID=$!
    PIDS+=("$SIM_PID")
    wait_for "$WORK/sim.err" "sim: serving on"
}

# gap_violations NAME_INDEX: the gap violations of the line's endpoint (0: the sim, 1: the master).
gaps() { "$PYTHON" -c 'import json,sys; print(json.load(open(sys.argv[1]))["endpoints"][int(sys.argv[2])]["gap_violations"])' "$WORK/line.json" "$1"; }

# run_gateway LABEL BAUD PARITY CLIENTS UNITS(,) SECONDS WARMUP [DEAD_UNIT DEAD_CLIENTS [GATEWAY_ARGS...]]:
# one run; prints a record.
run_gateway() {
    local label="$1" baud="$2" parity="$3" clients="$4" units="$5" seconds="$6" warmup="$7" dead="${8:-}" dead_clients="${9:-0}"
    shift $(( $# < 9 ? $# : 9 ))
    local gateway_args=("$@")
    local port queue=64 all_units
    start_line "$baud" "$parity"
    IFS=, read -r -a all_units <<<"$units"
    start_sim "$baud" "$parity" "${all_units[@]}"
    port="$("$PYTHON" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')"
    [ "$clients" -gt 64 ] && queue=$((clients + dead_clients))
    "$FERROBUS" --port "$B" --baud "$baud" --parity "$parity" gateway --listen "127.0.0.1:$port" \
        --queue "$queue" --max-connections 2000 --max-per-source 2000 "${gateway_args[@]}" 2>"$WORK/gw.err" &
    local gw=$!
    PIDS+=("$gw")
    wait_for "$WORK/gw.err" "gateway: listening on"
    local extra=()
    [ -n "$dead" ] && extra=(--dead-unit "$dead" --dead-clients "$dead_clients")
    local load
    load="$("$PYTHON" "$ROOT/bench/gateway_load.py" --addr "127.0.0.1:$port" --clients "$clients" --units "$units" --seconds "$seconds" --warmup "$warmup" "${extra[@]}")"
    stop "$gw" TERM
    stop "$SIM_PID" TERM
    stop "$LINE_PID" INT
    local line_tx
    line_tx="$(grep -o 'line [^:]*: queue [0-9]* (max [0-9]*); requests [0-9]*' "$WORK/gw.err" | head -1 || true)"
    printf '{"run":"%s","baud":%d,"parity":"%s","load":%s,"gap_violations_gateway":%s,"gap_violations_sim":%s,"gateway":"%s"}\n' \
        "$label" "$baud" "$parity" "$load" "$(gaps 1)" "$(gaps 0)" "$line_tx"
}

# run_direct BAUD PARITY: `ferrobus bench` straight on the line, for comparison.
run_direct() {
    local baud="$1" parity="$2" count
    start_line "$baud" "$parity"
    start_sim "$baud" "$parity" 1
    count=$(( baud > 19200 ? RUN * 140 : RUN * 20 ))
    local out
    out="$("$FERROBUS" --port "$B" --baud "$baud" --parity "$parity" bench --count "$count" --json 2>/dev/null)"
    stop "$SIM_PID" TERM
    stop "$LINE_PID" INT
    printf '{"run":"direct","baud":%d,"parity":"%s","bench":%s,"gap_violations_master":%s}\n' "$baud" "$parity" "$out" "$(gaps 1)"
}

log "machine: $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg); $("$FERROBUS" --version)"
LONG=$((RUN * 2))
for setting in "9600 even" "115200 none"; do
    read -r baud parity <<<"$setting"
    run_direct "$baud" "$parity"
    run_gateway clients-1 "$baud" "$parity" 1 1 "$RUN" 0
    run_gateway clients-10 "$baud" "$parity" 10 1 "$RUN" 0
    run_gateway clients-100 "$baud" "$parity" 100 1 "$LONG" 0
done
run_gateway clients-1000 115200 none 1000 1 "$LONG" 0
# A dead unit among ten live ones, with the gateway's defaults (3 timeouts of 1 s before the
# unit is skipped, then a probe after 5 s, 10 s, 20 s ... up to 60 s apart): the window opens
# after a warm-up in which the dead unit has cost its first timeouts and probes.
run_gateway ten-live 115200 none 10 1,2,3,4,5,6,7,8,9,10 "$LONG" "$LONG"
run_gateway ten-live-one-dead 115200 none 10 1,2,3,4,5,6,7,8,9,10 "$LONG" "$LONG" 11 1
