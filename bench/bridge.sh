#!/usr/bin/env bash
# `ferrobus bridge` at plant scale: 100 simulated 3G3RX drives on 4 paced lines, 20 points each
# at 1 s, published as Sparkplug B to a mosquitto of its own. Figures over a steady window:
# the bridge's CPU (share of one core), its memory, the end-to-end latency from a value
# changing in a simulator to its MQTT message, and how busy each line's wire is.
#
#   ferrobus line (4, paced, 8N1, a tap each) ── ferrobus sim: 25 units of omron-3g3rx,
#        │                                        d005 counting 1.1 s periods (--ticker)
#        └── ferrobus bridge --config plant.toml ──▶ mosquitto 127.0.0.1 ──▶ subscriber.py
#
# CPU: utime + stime of the bridge (/proc/PID/stat) over the window, divided by the window.
# Memory: VmRSS at the window's start and end, VmHWM and smaps_rollup at its end.
# Latency: the subscriber's receive instant minus the instant the received d005 value began
# (a known function of the system clock: bench/bridge/figures.py). Wire: the taps' frames in
# the window (characters plus a t3.5 after each frame) per second of the window.
# bench/BRIDGE.md has the method and the figures.
#
# Usage: bench/bridge.sh [--seconds N] [--baud B] [--lines N] [--units N] [--every D] [--tcp [--in-flight N]] [--poll] [--heaptrack] [--keep]
#   --seconds N  the steady window, after every DBIRTH has arrived and 5 s more (default 60)
#   --baud B     the lines' speed, 8N1 (default 115200)
#   --lines N, --units N  another plant: N lines (default 4), N drives on each (default 25);
#                the memory's share per line and per device, by subtraction
#   --every D    each device's poll period (default 1s; 100ms with --tcp)
#   --tcp        each line a Modbus/TCP connection to a `ferrobus sim --tcp` of its own instead
#                of a paced serial line: the bridge at scale, where the wire is not the limit
#                (--tcp --lines 10 --units 50: 500 drives × 20 points at 100 ms, 100 k points/s);
#                the polls made are read off the bridge's own --metrics at the window's ends
#   --in-flight N  with --tcp: the lines' in_flight (requests outstanding on each connection at
#                once; default 1)
#   --heaptrack  run the bridge under heaptrack and print its peak heap and biggest allocators
#                (allocation is slower under it: the CPU figure is not the bridge's then)
#   --poll       instead of the bridge, one `ferrobus poll` per line on the same points: the
#                setup checked without the bridge (CPU and memory are the four polls' sums)
#   --keep       keep the work directory (its path is printed)
# Environment:
#   FERROBUS=PATH  the ferrobus binary (default target/release/ferrobus, built if missing)
#   PYTHON=PATH    a Python with pysparkplug and paho-mqtt (default target/peers/sparkplug-venv)
#   MOSQUITTO=PATH the broker (default: mosquitto on PATH, else /usr/sbin/mosquitto)
#   RECORD=FILE    also append the figures as a JSON line to FILE
set -euo pipefail

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
WINDOW=60
BAUD=115200
MODE=bridge
KEEP=0
LINES=4
UNITS=25
HEAPTRACK=0
TRANSPORT=serial
EVERY=""
IN_FLIGHT=1
while [[ $# -gt 0 ]]; do
    case "$1" in
        --seconds) WINDOW="$2"; shift 2 ;;
        --baud) BAUD="$2"; shift 2 ;;
        --lines) LINES="$2"; shift 2 ;;
        --units) UNITS="$2"; shift 2 ;;
        --every) EVERY="$2"; shift 2 ;;
        --tcp) TRANSPORT=tcp; shift ;;
        --in-flight) IN_FLIGHT="$2"; shift 2 ;;
        --heaptrack) HEAPTRACK=1; shift ;;
        --poll) MODE=poll; shift ;;
        --keep) KEEP=1; shift ;;
        -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d'; exit 0 ;;
        *) echo "bridge.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done

if [[ $IN_FLIGHT != 1 && ($TRANSPORT != tcp || $MODE != bridge) ]]; then
    echo "bridge.sh: --in-flight is the bridge's Modbus/TCP lines' (with --tcp, without --poll)" >&2
    exit 2
fi
if [[ -z $EVERY ]]; then
    if [[ $TRANSPORT == tcp ]]; then EVERY=100ms; else EVERY=1s; fi
fi
TICKER_POINT=d005
TICKER_PERIOD=1.1
SETTLE=5
# 20 readable points of the 3G3RX, in six reads (the drive takes 4 registers per read): the
# status coils in two (0x0012 is unmapped), F001 and the status words, three monitors, three
# more (d005 is the ticker), and the trip counter with the last trip's factor and state.
READS_PER_DEVICE=6
POINTS=(running reverse ready run-signal at-speed above-setting overload pid-deviation
        F001 status-a status-b d001 d002 d003 d004 d005 d006 trip-count trip1-factor trip1-status)

FERROBUS="${FERROBUS:-$ROOT/target/release/ferrobus}"
if [[ ! -x "$FERROBUS" ]]; then
    (cd "$ROOT" && cargo build --release -p ferrobus-cli)
fi
PYTHON="${PYTHON:-$ROOT/target/peers/sparkplug-venv/bin/python}"
MOSQUITTO="${MOSQUITTO:-$(command -v mosquitto || echo /usr/sbin/mosquitto)}"
for tool in "$PYTHON" "$MOSQUITTO"; do
    [[ -x "$tool" ]] || { echo "bridge.sh: $tool is missing: run .ci/setup-peers.sh" >&2; exit 1; }
done
if [[ $HEAPTRACK == 1 ]] && ! command -v heaptrack >/dev/null; then
    echo "bridge.sh: --heaptrack needs heaptrack (Debian: apt-get install heaptrack)" >&2
    exit 1
fi

WORK="$(mktemp -d "${TMPDIR:-/tmp}/bridgebench.XXXXXX")"
PIDS=()
# Stops every process started, the last started first: the bridge before the broker and the
# lines it uses, the subscriber (which flushes its file) before the figures are read.
stop_all() {
    local i
    for ((i = ${#PIDS[@]} - 1; i >= 0; i--)); do
        kill -TERM "${PIDS[i]}" 2>/dev/null || true
        wait "${PIDS[i]}" 2>/dev/null || true
    done
    PIDS=()
}
cleanup() {
    stop_all
    if [[ $KEEP == 1 ]]; then echo "bridge.sh: work directory kept: $WORK" >&2; else rm -rf "$WORK"; fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Waits up to $2 s for file $1 to have $3 lines (default 1).
wait_lines() {
    local i
    for i in $(seq $(($2 * 20))); do
        [[ -f "$1" && $(wc -l <"$1") -ge ${3:-1} ]] && return 0
        sleep 0.05
    done
    echo "bridge.sh: timed out waiting for $1" >&2
    return 1
}
free_port() { "$PYTHON" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }

# ---- broker ------------------------------------------------------------------------------------
MQTT_PORT="$(free_port)"
cat >"$WORK/mosquitto.conf" <<EOF
listener $MQTT_PORT 127.0.0.1
allow_anonymous true
persistence false
log_dest stdout
EOF
"$MOSQUITTO" -c "$WORK/mosquitto.conf" >"$WORK/mosquitto.log" 2>&1 &
PIDS+=($!)
for _ in $(seq 100); do
    (exec 3<>"/dev/tcp/127.0.0.1/$MQTT_PORT") 2>/dev/null && break
    sleep 0.05
done

# ---- lines and simulators ----------------------------------------------------------------------
UNIT_ARGS=()
for u in $(seq "$UNITS"); do UNIT_ARGS+=(-u "$u"); done
declare -a MASTER
for l in $(seq "$LINES"); do
    if [[ $TRANSPORT == tcp ]]; then
        MASTER[l]="127.0.0.1:$(free_port)"
        "$FERROBUS" sim --profile omron-3g3rx "${UNIT_ARGS[@]}" --ticker "$TICKER_POINT:${TICKER_PERIOD}s" \
            --tcp "${MASTER[l]}" >"$WORK/sim$l.out" 2>"$WORK/sim$l.err" &
        PIDS+=($!)
        continue
    fi
    "$FERROBUS" --baud "$BAUD" --parity none line --drops 2 --tap --tap-record "$WORK/tap$l.jsonl" \
        --stats-json "$WORK/line$l.json" >"$WORK/line$l.out" 2>"$WORK/line$l.err" &
    PIDS+=($!)
    wait_lines "$WORK/line$l.out" 10 3
    MASTER[l]="$(sed -n 1p "$WORK/line$l.out")"
    # Nobody listens to the tap's pty: drain it, the record is written from the line itself.
    cat "$(sed -n 3p "$WORK/line$l.out")" >/dev/null &
    PIDS+=($!)
    "$FERROBUS" --port "$(sed -n 2p "$WORK/line$l.out")" --baud "$BAUD" --parity none \
        sim --profile omron-3g3rx "${UNIT_ARGS[@]}" --ticker "$TICKER_POINT:${TICKER_PERIOD}s" \
        >"$WORK/sim$l.out" 2>"$WORK/sim$l.err" &
    PIDS+=($!)
done
for l in $(seq "$LINES"); do
    if [[ $TRANSPORT == tcp ]]; then
        for _ in $(seq 200); do grep -q "listening on" "$WORK/sim$l.err" 2>/dev/null && break; sleep 0.05; done
    else
        wait_lines "$WORK/sim$l.err" 10 "$((UNITS + 1))"
    fi
done

# ---- the plant ---------------------------------------------------------------------------------
toml_list() { local p out=""; for p in "$@"; do out+="\"$p\", "; done; echo "[${out%, }]"; }
{
    echo "# Generated by bench/bridge.sh: $LINES $TRANSPORT lines × $UNITS drives × ${#POINTS[@]} points every $EVERY."
    echo "[broker]"
    echo "address = \"127.0.0.1:$MQTT_PORT\""
    echo
    echo "[sparkplug]"
    echo "group_id = \"bridgebench\""
    echo "edge_node_id = \"bench-edge\""
    for l in $(seq "$LINES"); do
        echo
        echo "[[line]]"
        echo "name = \"line$l\""
        if [[ $TRANSPORT == tcp ]]; then
            echo "tcp = \"${MASTER[l]}\""
            [[ $IN_FLIGHT == 1 ]] || echo "in_flight = $IN_FLIGHT"
        else
            echo "port = \"${MASTER[l]}\""
            echo "baud = $BAUD"
            echo "parity = \"none\""
            echo "stop_bits = 1"
        fi
        echo "timeout = \"100ms\""
        for u in $(seq "$UNITS"); do
            echo
            echo "[[line.device]]"
            printf 'id = "l%d-drive%02d"\n' "$l" "$u"
            echo "unit = $u"
            echo "profile = \"omron-3g3rx\""
            echo "every = \"$EVERY\""
            echo "points = $(toml_list "${POINTS[@]}")"
        done
    done
} >"$WORK/plant.toml"

# ---- subscriber, then the bridge (or the polls) ------------------------------------------------
"$PYTHON" "$ROOT/bench/bridge/subscriber.py" --port "$MQTT_PORT" --out "$WORK/messages.jsonl" \
    >"$WORK/subscriber.out" 2>"$WORK/subscriber.err" &
PIDS+=($!)
wait_lines "$WORK/subscriber.out" 10

MEASURED=()
POLL_RECORDS=()
# The bridge's status endpoint: its polls counted at the window's ends.
METRICS="127.0.0.1:$(free_port)"
if [[ $MODE == bridge ]]; then
    if [[ $HEAPTRACK == 1 ]]; then
        heaptrack -o "$WORK/heaptrack" "$FERROBUS" bridge --config "$WORK/plant.toml" \
            >"$WORK/bridge.out" 2>"$WORK/bridge.err" &
        PIDS+=($!)
        # The bridge is heaptrack's child.
        for _ in $(seq 100); do
            BRIDGE="$(pgrep -P "$!" -x ferrobus || true)"
            [[ -n "$BRIDGE" ]] && break
            sleep 0.05
        done
        MEASURED+=("$BRIDGE")
    else
        "$FERROBUS" bridge --config "$WORK/plant.toml" --metrics "$METRICS" >"$WORK/bridge.out" 2>"$WORK/bridge.err" &
        PIDS+=($!)
        MEASURED+=($!)
    fi
    # Every DBIRTH, then a few seconds for the first cycles to settle.
    for i in $(seq 1201); do
        [[ $(grep -c '/DBIRTH/' "$WORK/messages.jsonl" 2>/dev/null) -ge $((LINES * UNITS)) ]] && break
        [[ $i == 1201 ]] && { echo "bridge.sh: not every DBIRTH came within 60 s: measuring anyway" >&2; break; }
        kill -0 "${MEASURED[0]}" 2>/dev/null || { echo "bridge.sh: the bridge ended:" >&2; cat "$WORK/bridge.err" >&2; exit 1; }
        sleep 0.05
    done
else
    SPEC=()
    for u in $(seq "$UNITS"); do SPEC+=(--unit "$u" "${POINTS[@]}"); done
    for l in $(seq "$LINES"); do
        if [[ $TRANSPORT == tcp ]]; then WHERE=(--tcp "${MASTER[l]}"); else WHERE=(--port "${MASTER[l]}" --baud "$BAUD" --parity none); fi
        "$FERROBUS" "${WHERE[@]}" --device omron-3g3rx --timeout 100ms \
            poll --every "$EVERY" "${SPEC[@]}" --jsonl >"$WORK/poll$l.jsonl" 2>"$WORK/poll$l.err" &
        PIDS+=($!)
        MEASURED+=($!)
        POLL_RECORDS+=("$WORK/poll$l.jsonl")
    done
fi
sleep "$SETTLE"

cpu_ticks() { local p t=0; for p in "${MEASURED[@]}"; do t=$((t + $(awk '{print $14 + $15}' "/proc/$p/stat"))); done; echo $t; }
# Of it, in the kernel (stime): on loopback a send also runs the peer's receive.
sys_ticks() { local p t=0; for p in "${MEASURED[@]}"; do t=$((t + $(awk '{print $15}' "/proc/$p/stat"))); done; echo $t; }
status_kb() { local p t=0; for p in "${MEASURED[@]}"; do t=$((t + $(awk -v k="$1:" '$1 == k {print $2}' "/proc/$p/status"))); done; echo $t; }

# The polls the bridge made so far, by its own metrics (0 without them: the polls' mode).
polls_made() {
    [[ $MODE == bridge && $HEAPTRACK == 0 ]] || { echo 0; return; }
    curl -sf "http://$METRICS/metrics" | awk '/^ferrobus_bridge_polls_total/ {n += $2} END {printf "%d", n}'
}
POLLS0="$(polls_made)"
START_NS="$(date +%s%N)"
CPU0="$(cpu_ticks)"
SYS0="$(sys_ticks)"
RSS0="$(status_kb VmRSS)"
LOAD="$(cut -d' ' -f1-3 /proc/loadavg)"
echo "bridge.sh: $MODE, $((LINES * UNITS)) devices on $LINES $TRANSPORT lines, every $EVERY: measuring ${WINDOW} s (work: $WORK)" >&2
sleep "$WINDOW"
CPU1="$(cpu_ticks)"
SYS1="$(sys_ticks)"
END_NS="$(date +%s%N)"
POLLS1="$(polls_made)"
RSS1="$(status_kb VmRSS)"
HWM="$(status_kb VmHWM)"
# Where the memory of the (first) measured process is: anonymous (heap, stacks) or file-backed.
cp "/proc/${MEASURED[0]}/smaps" "$WORK/smaps.txt"
THREADS="$(awk '$1 == "Threads:" {print $2}' "/proc/${MEASURED[0]}/status")"
MEMORY="$(awk '$1 ~ /^(Rss|Anonymous|Shared_Clean|Private_Clean|Private_Dirty):$/ {sub(":", "", $1); printf "%s\"%s\": %s", n++ ? ", " : "", $1, $2}' "/proc/${MEASURED[0]}/smaps_rollup")"

# The bridge (or the polls) first, its last messages delivered, then everything else: the
# subscriber's file and the taps' records are complete once their writers have ended.
for p in "${MEASURED[@]}"; do kill -TERM "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
sleep 1
stop_all

OVERLOAD="$({ grep -h -i -E 'cannot carry|keep up|overload' "$WORK"/bridge.err "$WORK"/poll*.err 2>/dev/null || true; } \
    | head -5 | "$PYTHON" -c 'import json, sys; print(json.dumps([l.strip() for l in sys.stdin]))')"
LINES_JSON="$([[ $TRANSPORT == tcp ]] || for l in $(seq "$LINES"); do
    awk -v l="$l" -v tap="$WORK/tap$l.jsonl" '/^line: .* drops at/ {
        for (i = 1; i <= NF; i++) { if ($i == "character") c = $(i + 1); if ($i == "t3.5") t = $(i + 1) }
        printf "{\"name\": \"line%s\", \"tap\": \"%s\", \"char_us\": %s, \"t35_us\": %s}\n", l, tap, c, t }' "$WORK/line$l.err"
done | paste -sd, -)"
list_json() { local f out=""; for f in "$@"; do out+="\"$f\", "; done; echo "[${out%, }]"; }
cat >"$WORK/run.json" <<EOF
{"mode": "$MODE", "transport": "$TRANSPORT", "in_flight": $IN_FLIGHT, "every": "$EVERY", "baud": $BAUD, "devices": $((LINES * UNITS)), "points_per_device": ${#POINTS[@]},
 "polls_in_window": $((POLLS1 - POLLS0)), "reads_per_device": $READS_PER_DEVICE,
 "binary": "$FERROBUS", "load_average": "$LOAD",
 "window_start_ns": $START_NS, "window_end_ns": $END_NS,
 "cpu_ticks": $((CPU1 - CPU0)), "sys_ticks": $((SYS1 - SYS0)), "clk_tck": $(getconf CLK_TCK),
 "rss_start_kb": $RSS0, "rss_end_kb": $RSS1, "hwm_kb": $HWM, "memory_kb": {$MEMORY},
 "smaps": "$WORK/smaps.txt", "threads": $THREADS,
 "messages": "$WORK/messages.jsonl", "poll_records": $(list_json "${POLL_RECORDS[@]}"),
 "ticker_point": "$TICKER_POINT", "ticker_period_s": $TICKER_PERIOD,
 "lines": [$LINES_JSON], "overload_messages": $OVERLOAD}
EOF
"$PYTHON" "$ROOT/bench/bridge/figures.py" --run "$WORK/run.json" --json "$WORK/figures.json"
if [[ $MODE == bridge ]]; then
    echo
    echo "The bridge's own summary (the whole run, births included):"
    cat "$WORK/bridge.out"
fi
if [[ $HEAPTRACK == 1 ]]; then
    heaptrack_print --print-peaks=1 --peak-limit=12 --sub-peak-limit=2 --print-allocators=0 --print-temporary=0 --print-leaks=0 \
        -f "$(ls "$WORK"/heaptrack.*)" >"$WORK/heaptrack.txt" 2>&1 || true
    grep -E "peak heap memory|total memory leaked|calls to allocation" "$WORK/heaptrack.txt" || true
    # Each peak consumer with the top four frames of its biggest call stack.
    echo "heaptrack's peak consumers (the whole report: --keep, heaptrack.txt):"
    awk '/PEAK MEMORY CONSUMERS/ {on = 1} /^ *in \// {next} on && /consumed over/ {n = 5} on && n-- > 0' "$WORK/heaptrack.txt" | head -60
fi
if [[ -n "${RECORD:-}" ]]; then
    cat "$WORK/figures.json" >>"$RECORD"
    echo >>"$RECORD"
fi
