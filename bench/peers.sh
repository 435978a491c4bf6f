#!/usr/bin/env bash
# bench/peers.sh - ferrobus side by side with libmodbus, pymodbus, tokio-modbus and mbpoll.
#
# One run on one machine, FC03 reads of 10 holding registers from unit 1:
#
#   paced   ferrobus line (a virtual RS-485 line with real character timing) at 9600 8E1 and
#           115200 8N1: ferrobus client <-> ferrobus sim, every peer client (libmodbus,
#           pymodbus async, tokio-modbus, mbpoll) <-> ferrobus sim, ferrobus client <-> every
#           peer server. Rate, share of the theoretical rate, latency, and the inter-frame gaps
#           each side broke (the line's gap_violations).
#   unpaced a plain socat pty pair (bytes arrive at once), ferrobus with --t35 0ms: every client
#           (ferrobus, libmodbus, pymodbus, tokio-modbus) against every server (ferrobus sim,
#           libmodbus, pymodbus, tokio-modbus), and mbpoll against ferrobus sim. Rate and CPU
#           time per transaction of the master and of the slave.
#
# Writes bench/RESULTS.md (the tables, the goals with their ratios, the machine and every
# version), bench/results.svg (the plot, gnuplot) and bench/results.jsonl (one record per
# run); prints the tables. bench/README.md says what to install and how the figures are made.
#
# Environment:
#   FERROBUS=PATH  the ferrobus binary (default: cargo build --release -p ferrobus-cli, in
#                  $CARGO_TARGET_DIR or target/)
#   REPS=N         runs per pair on the paced line (default 3)
#   UNPACED_REPS=N runs per pair on the unpaced pty pair (default 5: shared machines are noisy)
#   QUICK=1        a smoke run: a tenth of the counts, one run per pair (under a minute)
#   ONLY=REGEX     only the runs whose "mode/line/client/server" matches (e.g. 'unpaced/.*/ferrobus/')
#   KEEP=1         keep the work directory (every log) and print its path
#   RESULTS_DIR=D  write RESULTS.md, results.svg and results.jsonl there (default: bench/)
#   PYTHON         python3 with pymodbus 3.16.1 (default python3)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BENCH="$ROOT/bench"
PEERS="$ROOT/target/peers"
PYTHON="${PYTHON:-python3}"
QUICK="${QUICK:-0}"
KEEP="${KEEP:-0}"
ONLY="${ONLY:-}"
REPS="${REPS:-3}"
RESULTS_DIR="${RESULTS_DIR:-$BENCH}"
UNPACED_REPS="${UNPACED_REPS:-5}"
TIMEOUT_MS=1000
QUANTITY=10

die() {
    printf 'peers.sh: error: %s\n' "$*" >&2
    exit 1
}
log() { printf 'peers.sh: %s\n' "$*" >&2; }
have() { command -v "$1" >/dev/null 2>&1; }

# ---- what this needs --------------------------------------------------------
have gnuplot || die "gnuplot is missing (it draws bench/results.svg): sudo apt-get install --no-install-recommends gnuplot-nox (see bench/README.md)"
have socat || die "socat is missing: run .ci/setup-peers.sh"
have mbpoll || die "mbpoll is missing: run .ci/setup-peers.sh"
have timeout || die "timeout (coreutils) is missing"
have "$PYTHON" || die "$PYTHON is missing"
"$PYTHON" -c 'import pymodbus' 2>/dev/null || die "pymodbus is not importable by $PYTHON: run .ci/setup-peers.sh"
LIB_SERVER="$PEERS/libmodbus_server"
LIB_CLIENT="$PEERS/libmodbus_client"
TOKIO="$PEERS/tokio-modbus-peer/release/tokio-modbus-peer"
for program in "$LIB_SERVER" "$LIB_CLIENT" "$TOKIO"; do
    [ -x "$program" ] || die "$program is missing: run .ci/setup-peers.sh"
done
if [ -z "${FERROBUS:-}" ]; then
    have cargo || die "cargo is missing, and FERROBUS does not name a ferrobus binary"
    log "building ferrobus (cargo build --release -p ferrobus-cli)"
    (cd "$ROOT" && cargo build --release --quiet -p ferrobus-cli) || die "cargo build failed"
    FERROBUS="${CARGO_TARGET_DIR:-$ROOT/target}/release/ferrobus"
fi
[ -x "$FERROBUS" ] || die "no ferrobus binary at $FERROBUS"
"$FERROBUS" bench --help >/dev/null 2>&1 || die "$FERROBUS has no bench command: rebuild it"

# ---- bookkeeping: every child is tracked and stopped on exit ----------------
WORK="$(mktemp -d "${TMPDIR:-/tmp}/ferrobus-bench.XXXXXX")"
PIDS=()
cleanup() {
    local pid
    for pid in "${PIDS[@]}"; do
        kill -TERM "$pid" 2>/dev/null || true
    done
    for pid in "${PIDS[@]}"; do
        wait "$pid" 2>/dev/null || true
    done
    if [ "$KEEP" = 1 ]; then
        log "logs kept in $WORK"
    else
        rm -rf "$WORK"
    fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM

track() { PIDS+=("$1"); }
untrack() {
    local pid keep=()
    for pid in "${PIDS[@]}"; do
        [ "$pid" = "$1" ] || keep+=("$pid")
    done
    PIDS=("${keep[@]}")
}

# alive PID: it runs (a child that has exited stays a zombie until it is reaped, and a
# zombie still answers kill -0).
alive() {
    local state
    state="$(sed 's/.*) //; s/ .*//' /proc/"$1"/stat 2>/dev/null || true)"
    [ -n "$state" ] && [ "$state" != Z ]
}

# stop PID SIGNAL: signal it, give it 5 s to exit, then SIGKILL; reap it.
stop() {
    local pid="$1" signal="$2" i
    kill -"$signal" "$pid" 2>/dev/null || true
    for ((i = 0; i < 100; i++)); do
        alive "$pid" || break
        sleep 0.05
    done
    if alive "$pid"; then
        log "pid $pid ignored SIG$signal for 5 s; killing it"
        kill -KILL "$pid" 2>/dev/null || true
    fi
    wait "$pid" 2>/dev/null || true
    untrack "$pid"
}

# ready_within SECONDS PID WHAT CHECK...: waits until CHECK succeeds; returns 1 (and says
# why) if PID exits first or the time runs out.
ready_within() {
    local limit="$1" pid="$2" what="$3"
    shift 3
    local deadline=$((SECONDS + limit))
    until "$@"; do
        if ! alive "$pid"; then
            log "$what exited before it was ready"
            return 1
        fi
        if [ "$SECONDS" -ge "$deadline" ]; then
            log "$what not ready after ${limit} s"
            return 1
        fi
        sleep 0.02
    done
}
# wait_until SECONDS PID WHAT CHECK...: the same, fatal.
wait_until() {
    ready_within "$@" || die "giving up (KEEP=1 keeps the logs in the work directory)"
}
# show_log FILE: its last lines, indented, on stderr.
show_log() { tail -n 15 "$1" 2>/dev/null | sed 's/^/    | /' >&2 || true; }
lines_at_least() { [ -f "$1" ] && [ "$(wc -l <"$1")" -ge "$2" ]; }
has_text() { [ -f "$1" ] && grep -q "$2" "$1"; }
both_exist() { [ -e "$1" ] && [ -e "$2" ]; }

# cpu_ns PID: CPU time (user + system, every live thread) of a process in nanoseconds, from
# /proc/PID/task/*/schedstat (nanosecond resolution, unlike /proc/PID/stat's 10 ms ticks).
cpu_ns() {
    local total=0 run rest f
    for f in /proc/"$1"/task/*/schedstat; do
        read -r run rest <"$f" 2>/dev/null || continue
        total=$((total + run))
    done
    echo "$total"
}

# ---- the programs, by role --------------------------------------------------
# serial_args PROGRAM BAUD PARITY(N|E): the line settings in each program's syntax.
serial_args() {
    local program="$1" baud="$2" parity="$3" word=none
    [ "$parity" = E ] && word=even
    case "$program" in
        ferrobus) echo "--baud $baud --parity $word" ;;
        mbpoll) echo "-b $baud -P $word" ;;
        *) echo "--baud $baud --parity $parity" ;;
    esac
}

# start_server NAME PATH BAUD PARITY T35ARGS: starts it in the background and waits until it
# serves, three attempts (a loaded machine sometimes fails one); sets SERVER_PID.
start_server() {
    local attempt
    for attempt in 1 2 3; do
        start_server_once "$@" && return 0
        log "$1 server, attempt $attempt of 3 failed; its stderr:"
        show_log "$WORK/server.err"
        stop "$SERVER_PID" TERM
        sleep 0.5
    done
    die "the $1 server does not start"
}

# start_server_once: one attempt. The option lists ($serial, $t35) are split into words on
# purpose.
start_server_once() {
    local name="$1" path="$2" baud="$3" parity="$4" t35="$5" out="$WORK/server.out" err="$WORK/server.err"
    local serial
    serial="$(serial_args "$name" "$baud" "$parity")"
    : >"$out"
    : >"$err"
    # shellcheck disable=SC2086
    case "$name" in
        ferrobus) "$FERROBUS" --port "$path" $serial $t35 sim --profile generic >"$out" 2>"$err" & ;;
        libmodbus) "$LIB_SERVER" --rtu "$path" $serial >"$out" 2>"$err" & ;;
        pymodbus) "$PYTHON" "$ROOT/tests/peers/pymodbus_server.py" --rtu "$path" $serial >"$out" 2>"$err" & ;;
        tokio) "$TOKIO" server --rtu "$path" $serial >"$out" 2>"$err" & ;;
        *) die "unknown server $name" ;;
    esac
    SERVER_PID=$!
    track "$SERVER_PID"
    if [ "$name" = ferrobus ]; then
        ready_within 20 "$SERVER_PID" "ferrobus sim" has_text "$err" 'sim: serving on'
    else
        ready_within 20 "$SERVER_PID" "$name server" has_text "$out" '^READY$'
    fi
}

# run_client NAME PATH BAUD PARITY T35ARGS COUNT MBPOLL_SECONDS: runs the bench (in the
# background, tracked, so that a signal to this script stops it too) and writes its JSON
# object to $WORK/bench.json.
run_client() {
    local name="$1" path="$2" baud="$3" parity="$4" t35="$5" count="$6" seconds="$7"
    local out="$WORK/client.out" err="$WORK/client.err" serial pid rc=0
    serial="$(serial_args "$name" "$baud" "$parity")"
    local bench=(bench --count "$count" --address 0 --quantity "$QUANTITY")
    : >"$out"
    # shellcheck disable=SC2086
    case "$name" in
        ferrobus) "$FERROBUS" --port "$path" $serial $t35 --timeout "${TIMEOUT_MS}ms" "${bench[@]}" --json >"$out" 2>"$err" & ;;
        libmodbus) "$LIB_CLIENT" --rtu "$path" $serial --timeout-ms "$TIMEOUT_MS" "${bench[@]}" >"$out" 2>"$err" & ;;
        pymodbus) "$PYTHON" "$ROOT/tests/peers/pymodbus_client.py" --rtu "$path" $serial --timeout-ms "$TIMEOUT_MS" "${bench[@]}" >"$out" 2>"$err" & ;;
        tokio) "$TOKIO" client --rtu "$path" $serial --timeout-ms "$TIMEOUT_MS" "${bench[@]}" >"$out" 2>"$err" & ;;
        mbpoll)
            run_mbpoll "$path" "$serial" "$seconds"
            return
            ;;
        *) die "unknown client $name" ;;
    esac
    pid=$!
    track "$pid"
    wait "$pid" || rc=$?
    untrack "$pid"
    if ! grep '^{' "$out" | tail -n 1 >"$WORK/bench.json" || ! [ -s "$WORK/bench.json" ]; then
        log "$name client printed no result (exit $rc); its stderr:"
        show_log "$err"
        die "$name client failed"
    fi
}

# mbpoll has no bench mode and sleeps at least 10 ms (-l 10, its minimum) after every poll.
# It polls for SECONDS (timeout stops it, so it cannot outlive this script by more); the polls
# are counted, and its own time per transaction is derived by taking away the sleep as this
# machine really sleeps it (OVERSHOOT_US, measured once). bash's `time` gives its wall, user
# and system time.
run_mbpoll() {
    local path="$1" serial="$2" seconds="$3" out="$WORK/client.out" err="$WORK/client.err" times="$WORK/mbpoll.time"
    local TIMEFORMAT='%3R %3U %3S' pid
    : >"$times"
    # shellcheck disable=SC2086
    { time timeout -s INT "$seconds" mbpoll -m rtu -a 1 -r 1 -c "$QUANTITY" -t 4 $serial -l 10 -o 1 -q "$path" >"$out" 2>"$err"; } 2>"$times" &
    pid=$!
    track "$pid"
    wait "$pid" || true
    untrack "$pid"
    [ -s "$times" ] || die "mbpoll was not timed (see $err; KEEP=1 keeps it)"
    "$PYTHON" "$BENCH/report.py" mbpoll --out "$out" --err "$err" --times "$times" --quantity "$QUANTITY" \
        --poll-ms 10 --overshoot-us "$OVERSHOOT_US" --connect-ms 20 >"$WORK/bench.json"
}

# ---- one run ----------------------------------------------------------------
RESULTS="$WORK/results.jsonl"
: >"$RESULTS"

# run_pair MODE LINE BAUD PARITY CLIENT SERVER COUNT REP MBPOLL_SECONDS: a fresh line (or pty
# pair), a fresh server, one client run; appends one record to $RESULTS.
run_pair() {
    local mode="$1" line="$2" baud="$3" parity="$4" client="$5" server="$6" count="$7" rep="$8" seconds="$9"
    local key="$mode/$line/$client/$server"
    if [ -n "$ONLY" ] && ! [[ "$key" =~ $ONLY ]]; then
        return
    fi
    local medium_pid a b t35="" stats="null" word=none
    [ "$parity" = E ] && word=even
    if [ "$mode" = paced ]; then
        # Emptied here, not by the redirection: the child truncates its output only after the
        # fork, and the wait below must not read the previous run's paths.
        rm -f "$WORK/line.json"
        : >"$WORK/line.out"
        "$FERROBUS" line --drops 2 --baud "$baud" --parity "$word" --stats-json "$WORK/line.json" >"$WORK/line.out" 2>"$WORK/line.err" &
        medium_pid=$!
        track "$medium_pid"
        wait_until 10 "$medium_pid" "ferrobus line" lines_at_least "$WORK/line.out" 2
        a="$(sed -n 1p "$WORK/line.out")"
        b="$(sed -n 2p "$WORK/line.out")"
    else
        t35="--t35 0ms"
        rm -f "$WORK/a" "$WORK/b"
        socat -d -d "pty,raw,echo=0,link=$WORK/a" "pty,raw,echo=0,link=$WORK/b" 2>"$WORK/socat.log" &
        medium_pid=$!
        track "$medium_pid"
        wait_until 10 "$medium_pid" "socat" both_exist "$WORK/a" "$WORK/b"
        a="$WORK/a"
        b="$WORK/b"
    fi
    start_server "$server" "$a" "$baud" "$parity" "$t35"
    local cpu0 cpu1 bench
    cpu0="$(cpu_ns "$SERVER_PID")"
    run_client "$client" "$b" "$baud" "$parity" "$t35" "$count" "$seconds"
    bench="$(cat "$WORK/bench.json")"
    cpu1="$(cpu_ns "$SERVER_PID")"
    stop "$SERVER_PID" TERM
    # ferrobus sim prints, on exit, how late its replies went out after they were due.
    local late="null"
    if [ "$server" = ferrobus ]; then
        late="$(sed -n 's/.*after its due time.*: p50 \([0-9]*\) µs, p99 \([0-9]*\) µs.*/[\1,\2]/p' "$WORK/server.err" | tail -n 1)"
        [ -n "$late" ] || late="null"
    fi
    if [ "$mode" = paced ]; then
        stop "$medium_pid" INT
        if ! [ -s "$WORK/line.json" ]; then
            show_log "$WORK/line.err"
            die "ferrobus line wrote no statistics"
        fi
        stats="$(cat "$WORK/line.json")"
    else
        stop "$medium_pid" TERM
    fi
    printf '{"mode":"%s","line":"%s","baud":%d,"parity":"%s","client":"%s","server":"%s","rep":%d,"bench":%s,"server_cpu_s":%s,"sim_late_us":%s,"line_stats":%s}\n' \
        "$mode" "$line" "$baud" "$parity" "$client" "$server" "$rep" "$bench" \
        "$(awk -v a="$cpu0" -v b="$cpu1" 'BEGIN { printf "%.6f", (b - a) / 1e9 }')" "$late" "$stats" >>"$RESULTS"
    log "$(printf '%-7s %-10s %-9s -> %-9s #%d %s' "$mode" "$line" "$client" "$server" "$rep" "$bench")"
}

# ---- the plan -----------------------------------------------------------------
scale() { # scale N: N, or a tenth of it (at least 20) with QUICK=1
    if [ "$QUICK" = 1 ]; then echo $(($1 / 10 > 20 ? $1 / 10 : 20)); else echo "$1"; fi
}
quick_or() { if [ "$QUICK" = 1 ]; then echo "$1"; else echo "$2"; fi; }
if [ "$QUICK" = 1 ]; then
    REPS=1
    UNPACED_REPS=1
fi
START=$SECONDS
log "work directory $WORK"
OVERSHOOT_US="$("$PYTHON" "$BENCH/report.py" sleep-overshoot --ms 10 --samples 100)"
log "a 10 ms sleep overshoots by ${OVERSHOOT_US} µs here (median of 100; taken off mbpoll's polls)"

PEER_CLIENTS=(libmodbus pymodbus tokio mbpoll)
PEER_SERVERS=(libmodbus pymodbus tokio)

paced_pairs() { # paced_pairs LINE BAUD PARITY COUNT MBPOLL_SECONDS REPS
    local line="$1" baud="$2" parity="$3" count="$4" seconds="$5" reps="$6" rep c s
    for ((rep = 1; rep <= reps; rep++)); do
        run_pair paced "$line" "$baud" "$parity" ferrobus ferrobus "$count" "$rep" "$seconds"
        for c in "${PEER_CLIENTS[@]}"; do
            run_pair paced "$line" "$baud" "$parity" "$c" ferrobus "$count" "$rep" "$seconds"
        done
        for s in "${PEER_SERVERS[@]}"; do
            run_pair paced "$line" "$baud" "$parity" ferrobus "$s" "$count" "$rep" "$seconds"
        done
        # The floor of the instrument: libmodbus keeps no silent interval on either side, so
        # what it loses to the wire time of its 33 characters is the ptys' and the line's own
        # latency, which every pair pays.
        run_pair paced "$line" "$baud" "$parity" libmodbus libmodbus "$count" "$rep" "$seconds"
    done
}
# 9600 8E1: 45.8 ms per transaction at best, so REPS runs of 100 per pair (4.6 s each): one
# run on a shared machine can be a slow one;
# 115200 8N1: 6.4 ms, so REPS runs of 400 (2.5 s).
paced_pairs 9600-8E1 9600 E "$(scale 100)" "$(quick_or 1 5)" "$REPS"
paced_pairs 115200-8N1 115200 N "$(scale 400)" "$(quick_or 1 3)" "$REPS"

# Unpaced: every client against every server, UNPACED_REPS times, interleaved so that a noisy
# moment on a shared machine spreads over all pairs. pymodbus on either side is ~3x slower,
# so it gets fewer transactions: each run lasts 1.5-3 s here.
unpaced_count() { # unpaced_count CLIENT SERVER
    if [ "$1" = pymodbus ] || [ "$2" = pymodbus ]; then scale 4000; else scale 10000; fi
}
for ((rep = 1; rep <= UNPACED_REPS; rep++)); do
    for s in ferrobus "${PEER_SERVERS[@]}"; do
        for c in ferrobus libmodbus pymodbus tokio; do
            run_pair unpaced pty 115200 N "$c" "$s" "$(unpaced_count "$c" "$s")" "$rep" 0
        done
    done
    run_pair unpaced pty 115200 N mbpoll ferrobus 0 "$rep" "$(quick_or 1 2)"
done
ELAPSED=$((SECONDS - START))

# ---- the report -----------------------------------------------------------------
[ -s "$RESULTS" ] || die "no run matched ONLY='$ONLY'"
mkdir -p "$RESULTS_DIR"
cp "$RESULTS" "$RESULTS_DIR/results.jsonl"
"$PYTHON" "$BENCH/report.py" report --results "$RESULTS_DIR/results.jsonl" --markdown "$RESULTS_DIR/RESULTS.md" \
    --plot "$RESULTS_DIR/results.svg" --elapsed "$ELAPSED" --ferrobus "$FERROBUS" --root "$ROOT" \
    --overshoot-us "$OVERSHOOT_US" --reps "$REPS/$UNPACED_REPS" --quick "$QUICK"
log "done in ${ELAPSED} s: $RESULTS_DIR/RESULTS.md, results.svg, results.jsonl"
