#!/usr/bin/env bash
# tests/peers/selfcheck.sh - prove the peer fixtures right by pairing them.
#
# Every server (libmodbus, pymodbus, tokio-modbus) is paired with every client
# (the same three), over RTU on a socat pty pair and over TCP on a free port on
# 127.0.0.1: 3 x 3 x 2 = 18 runs. Each run starts a fresh server, feeds the
# client a script that covers every function code both sides support, and
# compares each result line with the value the shared data map predicts
# (README.md), including an exception 02 case, a timeout against a wrong unit
# id and a broadcast write. Known peer bugs are expected explicitly (see the
# quirk table below) so that a change in a peer shows up as a failure.
# Also checked: each server prints exactly "READY" on stdout and exits 0 on
# SIGTERM; each program rejects a bad argument with exit status 2.
#
# Needs the fixtures built by .ci/setup-peers.sh. Prints a pass/fail table and
# exits non-zero on any failure. Set KEEP=1 to keep the work directory (logs),
# ONLY=GLOB to run only the matching SERVER/CLIENT/TRANSPORT runs (for example
# ONLY='pymodbus/*/rtu').
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
PEERS="$ROOT/tests/peers"
BIN="$ROOT/target/peers"
PYTHON="${PYTHON:-python3}"
LIB_SERVER="$BIN/libmodbus_server"
LIB_CLIENT="$BIN/libmodbus_client"
TOKIO="$BIN/tokio-modbus-peer/release/tokio-modbus-peer"

UNIT=17         # the servers' unit id (not the default 1, to prove --unit works)
WRONG_UNIT=18   # nobody answers this one
TIMEOUT_MS=300  # client response timeout
SERIAL=(--baud 115200 --parity E) # parity E also exercises pymodbus's fallback to N on a pty

SERVERS=(libmodbus pymodbus tokio)
CLIENTS=(libmodbus pymodbus tokio)
TRANSPORTS=(rtu tcp)

# Function codes each side speaks (see README.md). "--" marks commands that
# do not touch the bus.
declare -A SERVER_FCS=(
    [libmodbus]="01 02 03 04 05 06 0F 10 11 16 17"
    [pymodbus]="01 02 03 04 05 06 07 08 0F 10 11 14 15 16 17 18 2B"
    [tokio]="01 02 03 04 05 06 07 08 0F 10 11 16 17 2B"
)
declare -A CLIENT_FCS=(
    [libmodbus]="01 02 03 04 05 06 07 0F 10 11 16 17"
    [pymodbus]="01 02 03 04 05 06 07 08 0F 10 11 14 15 16 17 18 2B"
    [tokio]="01 02 03 04 05 06 07 08 0F 10 11 16 17 18 2B"
)

# ---- bookkeeping ----------------------------------------------------------
WORK="$(mktemp -d "${TMPDIR:-/tmp}/peers-selfcheck.XXXXXX")"
PIDS=()
cleanup() {
    local pid
    for pid in "${PIDS[@]}"; do
        kill -TERM "$pid" 2>/dev/null
    done
    for pid in "${PIDS[@]}"; do
        wait "$pid" 2>/dev/null
    done
    if [ "${KEEP:-0}" = 1 ]; then
        echo "selfcheck: logs kept in $WORK" >&2
    else
        rm -rf "$WORK"
    fi
}
trap cleanup EXIT
trap 'exit 130' INT TERM

forget_pid() { # remove $1 from PIDS
    local keep=() p
    for p in "${PIDS[@]}"; do [ "$p" = "$1" ] || keep+=("$p"); done
    PIDS=("${keep[@]}")
}

die() {
    echo "selfcheck: $*" >&2
    exit 2
}

for f in "$LIB_SERVER" "$LIB_CLIENT" "$TOKIO"; do
    [ -x "$f" ] || die "$f missing: run .ci/setup-peers.sh first"
done
command -v socat >/dev/null || die "socat missing: run .ci/setup-peers.sh first"
"$PYTHON" -c 'import pymodbus, serial' 2>/dev/null || die "pymodbus missing: run .ci/setup-peers.sh first"

# ---- expected values from the data map --------------------------------------
holding() { echo $((($1 * 7 + 3) & 0xFFFF)); }
input() { echo $(((0x1000 + $1) & 0xFFFF)); }
coil() { echo $(($1 % 3 == 0 ? 1 : 0)); }
discrete() { echo $(($1 % 5 == 0 ? 1 : 0)); }
series() { # series FN FROM COUNT -> "v v v"
    local fn=$1 i out=()
    for ((i = $2; i < $2 + $3; i++)); do out+=("$($fn "$i")"); done
    echo "${out[*]}"
}
hexbytes() { # hexbytes TEXT -> "70 79 ..."
    printf '%s' "$1" | od -An -tx1 -v | tr -s ' \n' '  ' | sed 's/^ //; s/ $//'
}
hexstr() { printf '%s' "$1" | od -An -tx1 -v | tr -d ' \n'; }
words() { # words TEXT -> big-endian 16-bit words, decimal (TEXT has an even length)
    local -a b
    local i out=()
    read -r -a b <<<"$(hexbytes "$1")"
    for ((i = 0; i + 1 < ${#b[@]}; i += 2)); do out+=($((16#${b[i]}${b[i + 1]}))); done
    echo "${out[*]}"
}

LIBMODBUS_VERSION="$(pkg-config --modversion libmodbus)"
PYMODBUS_MM="$("$PYTHON" -c 'import pymodbus; print(".".join(pymodbus.__version__.split(".")[:2]))')"
UNIT_HEX="$(printf '%02x' "$UNIT")"

# FC 11 payloads (the bytes after the byte count).
declare -A SLAVE_ID=(
    [libmodbus]="ok b4 ff $(hexbytes "LMB$LIBMODBUS_VERSION")" # id 180, run ON, "LMB<version>"
    [pymodbus]="ok $(hexbytes "pymodbus-PM-$PYMODBUS_MM") ff" # identity joined by '-', run ON LAST
    [tokio]="ok $UNIT_HEX ff $(hexbytes "tokio-modbus")"       # id = unit, run ON, vendor
)
# FC 2B/0E basic objects.
declare -A DEVICE_ID=(
    [pymodbus]="ok 00=$(hexstr pymodbus) 01=$(hexstr PM) 02=$(hexstr "$PYMODBUS_MM")"
    [tokio]="ok 00=$(hexstr tokio-modbus) 01=$(hexstr TM) 02=$(hexstr 0.17)"
)

# The script. Format: FC|command|expected. Expected "{SID}", "{DEVID}" and
# "{BCAST}" depend on the server; a trailing '*' makes it a prefix match.
script_cases() {
    cat <<EOF
03|read_holding 0 5|ok $(series holding 0 5)
03|read_holding 995 5|ok $(series holding 995 5)
04|read_input 0 3|ok $(series input 0 3)
04|read_input 997 3|ok $(series input 997 3)
01|read_coils 0 10|ok $(series coil 0 10)
01|read_coils 1990 10|ok $(series coil 1990 10)
02|read_discrete 0 11|ok $(series discrete 0 11)
02|read_discrete 1995 5|ok $(series discrete 1995 5)
06|write_register 10 4660|ok
03|read_holding 10 1|ok 4660
10|write_registers 20 1 2 3|ok
03|read_holding 19 5|ok $(holding 19) 1 2 3 $(holding 23)
05|write_coil 1 1|ok
05|write_coil 0 0|ok
01|read_coils 0 4|ok 0 1 0 1
0F|write_coils 30 0 1 1 0 1|ok
01|read_coils 29 7|ok $(coil 29) 0 1 1 0 1 $(coil 35)
16|mask_write 40 0x00F2 0x0025|ok
03|read_holding 40 1|ok $(((($(holding 40) & 0xF2) | (0x25 & ~0xF2)) & 0xFFFF))
17|write_read 60 3 61 100 101|ok $(holding 60) 100 101
11|report_slave_id|{SID}
03|read_holding 1000 1|exception 2
03|read_holding 998 3|exception 2
01|read_coils 1999 2|exception 2
06|write_register 1000 1|exception 2
07|read_exception_status|ok 0
08|diag 0 4660|ok 0 4660
2B|read_device_id 1 0|{DEVID}
18|read_fifo 0|ok 0 1 2 3
14|read_file 1 0 2|ok $(words "SERVER DUMMY RECORD.")
15|write_file 1 0 1 2|ok
--|unit $WRONG_UNIT|ok
03|read_holding 0 1|timeout
--|sleep 600|ok
--|unit 0|ok
06|write_register 5 555|timeout
--|unit $UNIT|ok
03|read_holding 5 1|{BCAST}
03|read_holding 0 2|ok $(series holding 0 2)
EOF
}
# Notes on the script:
# - "sleep 600" after the request for another unit: libmodbus's RTU server
#   takes the next frame within its 500 ms response timeout for that unit's
#   reply and drops it.
# - pymodbus's read_file: the server ignores the length and always returns
#   the 20 bytes "SERVER DUMMY RECORD."; read_fifo always returns 0 1 2 3.
# - Broadcast (unit 0): every client waits for a reply and times out; only
#   the RTU libmodbus and tokio servers execute the write (pymodbus ignores
#   broadcast, and on TCP the fixtures answer unit U only).

# quirk SERVER CLIENT TRANSPORT FC -> "" | "skip REASON" | "expect VALUE|REASON"
quirk() {
    case "$1/$2/$3/$4" in
    pymodbus/tokio/*/11) echo "expect error*|tokio-modbus rejects pymodbus's FC 11 reply (run indicator must be 00/FF; pymodbus sends it last)" ;;
    tokio/tokio/tcp/11) echo "expect error*|tokio-modbus TCP server sends FC 11 with an MBAP length one byte short" ;;
    tokio/pymodbus/tcp/11) echo "expect timeout|tokio-modbus TCP server's short MBAP length: pymodbus cannot decode the FC 11 reply and drops it" ;;
    pymodbus/pymodbus/rtu/18) echo "expect timeout|pymodbus RTU client sizes the FC 18 response 2 bytes short and drops it" ;;
    tokio/*/rtu/08) echo "skip|tokio-modbus RTU server cannot frame FC 08 (would be line noise)" ;;
    *) ;;
    esac
}

# build SERVER CLIENT TRANSPORT: writes $WORK/script.txt and $WORK/expected.txt
build() {
    local server=$1 client=$2 transport=$3 fc cmd expect q bcast
    : >"$WORK/script.txt"
    : >"$WORK/expected.txt"
    if [ "$transport" = rtu ] && [ "$server" != pymodbus ]; then bcast=555; else bcast=$(holding 5); fi
    while IFS='|' read -r fc cmd expect; do
        if [ "$fc" != "--" ]; then
            case " ${SERVER_FCS[$server]} " in *" $fc "*) ;; *) continue ;; esac
            case " ${CLIENT_FCS[$client]} " in *" $fc "*) ;; *) continue ;; esac
        fi
        q="$(quirk "$server" "$client" "$transport" "$fc")"
        case "$q" in
        skip*)
            NOTES+=("$server server / $client client / $transport: FC $fc skipped: ${q#skip|}")
            continue
            ;;
        expect*)
            q="${q#expect }"
            expect="${q%%|*}"
            NOTES+=("$server server / $client client / $transport: FC $fc expects '$expect': ${q#*|}")
            ;;
        esac
        expect="${expect//\{SID\}/${SLAVE_ID[$server]}}"
        expect="${expect//\{DEVID\}/${DEVICE_ID[$server]:-}}"
        expect="${expect//\{BCAST\}/ok $bcast}"
        printf '%s\n' "$cmd" >>"$WORK/script.txt"
        printf '%s\n' "$expect" >>"$WORK/expected.txt"
    done < <(script_cases)
}

# ---- process helpers --------------------------------------------------------
CMD=()
server_cmd() { # server_cmd NAME TRANSPORT ENDPOINT -> CMD
    local conn
    if [ "$2" = rtu ]; then conn=(--rtu "$3" "${SERIAL[@]}"); else conn=(--tcp "$3"); fi
    case "$1" in
    libmodbus) CMD=("$LIB_SERVER" "${conn[@]}" --unit "$UNIT") ;;
    pymodbus) CMD=("$PYTHON" "$PEERS/pymodbus_server.py" "${conn[@]}" --unit "$UNIT") ;;
    tokio) CMD=("$TOKIO" server "${conn[@]}" --unit "$UNIT") ;;
    esac
}
client_cmd() { # client_cmd NAME TRANSPORT ENDPOINT -> CMD
    local conn
    if [ "$2" = rtu ]; then conn=(--rtu "$3" "${SERIAL[@]}"); else conn=(--tcp "$3"); fi
    case "$1" in
    libmodbus) CMD=("$LIB_CLIENT" "${conn[@]}") ;;
    pymodbus) CMD=("$PYTHON" "$PEERS/pymodbus_client.py" "${conn[@]}") ;;
    tokio) CMD=("$TOKIO" client "${conn[@]}") ;;
    esac
    CMD+=(--unit "$UNIT" --timeout-ms "$TIMEOUT_MS" script)
}

free_port() {
    "$PYTHON" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'
}

wait_for() { # wait_for TENTHS CONDITION...
    local n=$1
    shift
    while ! "$@"; do
        n=$((n - 1))
        [ "$n" -gt 0 ] || return 1
        sleep 0.1
    done
}
links_exist() { [ -e "$WORK/a" ] && [ -e "$WORK/b" ]; }
SERVER_PID=""
# Ready, or dead (then the caller reports it at once instead of waiting).
server_up() { grep -q '^READY$' "$WORK/server.out" 2>/dev/null || exited "$SERVER_PID"; }

# exited PID: true once PID is gone or a zombie (Linux /proc). A zombie still
# answers kill -0, so that cannot be used to see an exit before reaping.
exited() {
    local st
    st="$(cat "/proc/$1/stat" 2>/dev/null)" || return 0
    st="${st##*) }" # the state follows the parenthesised command name
    [ "${st%% *}" = Z ]
}

# stop PID: SIGTERM, reap, and return the exit status. A process that is
# still there after 5 s gets SIGKILL (status 137), so a server that ignores
# SIGTERM fails the check instead of hanging it. No helper subshell: a
# subshell would inherit the EXIT trap and run cleanup when killed.
stop() {
    local pid=$1 n=50
    kill -TERM "$pid" 2>/dev/null
    while ! exited "$pid" && [ "$n" -gt 0 ]; do
        sleep 0.1
        n=$((n - 1))
    done
    exited "$pid" || kill -KILL "$pid" 2>/dev/null
    wait "$pid" 2>/dev/null
    local rc=$?
    forget_pid "$pid"
    return "$rc"
}

SOCAT_PID=""
start_line() { # a fresh pty pair per run: no state carried between runs
    rm -f "$WORK/a" "$WORK/b"
    socat -d -d "pty,raw,echo=0,link=$WORK/a" "pty,raw,echo=0,link=$WORK/b" 2>"$WORK/socat.log" &
    SOCAT_PID=$!
    PIDS+=("$SOCAT_PID")
    wait_for 50 links_exist
}
stop_line() {
    [ -n "$SOCAT_PID" ] || return 0
    stop "$SOCAT_PID"
    SOCAT_PID=""
}

# ---- one run ------------------------------------------------------------------
declare -A RESULT
FAILS=()
NOTES=()

run_pair() { # run_pair SERVER CLIENT TRANSPORT
    local server=$1 client=$2 transport=$3 endpoint server_pid rc n_total n_bad=0 i
    local key="$server/$client/$transport"
    build "$server" "$client" "$transport"
    n_total=$(wc -l <"$WORK/expected.txt")

    if [ "$transport" = rtu ]; then
        if ! start_line; then
            RESULT[$key]="FAIL socat"
            FAILS+=("$key: socat pty pair did not come up")
            stop_line
            return
        fi
        endpoint="$WORK/a"
    else
        endpoint="$(free_port)"
    fi

    server_cmd "$server" "$transport" "$endpoint"
    # A fresh file: a READY left over from the previous run must not count
    # (the new process may not even have opened its stdout yet).
    rm -f "$WORK/server.out" "$WORK/server.err"
    "${CMD[@]}" >"$WORK/server.out" 2>"$WORK/server.err" &
    server_pid=$!
    SERVER_PID=$server_pid
    PIDS+=("$server_pid")
    if ! wait_for 150 server_up || exited "$server_pid"; then
        RESULT[$key]="FAIL start"
        FAILS+=("$key: server did not print READY; stderr: $(tail -n 3 "$WORK/server.err" | tr '\n' ' ')")
        stop "$server_pid"
        stop_line
        return
    fi

    [ "$transport" = rtu ] && endpoint="$WORK/b" || endpoint="127.0.0.1:$endpoint"
    client_cmd "$client" "$transport" "$endpoint"
    timeout 60 "${CMD[@]}" <"$WORK/script.txt" >"$WORK/actual.txt" 2>"$WORK/client.err"
    rc=$?

    stop "$server_pid"
    local server_rc=$?
    stop_line

    local -a cmds exp act
    mapfile -t cmds <"$WORK/script.txt"
    mapfile -t exp <"$WORK/expected.txt"
    mapfile -t act <"$WORK/actual.txt"
    for ((i = 0; i < n_total; i++)); do
        local e="${exp[$i]}" a="${act[$i]-<no line>}"
        if [[ "$e" == *'*' ]]; then
            [[ "$a" == "${e%\*}"* ]] && continue
        else
            [ "$a" = "$e" ] && continue
        fi
        n_bad=$((n_bad + 1))
        FAILS+=("$key: '${cmds[$i]}' -> '$a' (expected '$e')")
    done
    if [ "${#act[@]}" -ne "$n_total" ]; then
        n_bad=$((n_bad + 1))
        FAILS+=("$key: client printed ${#act[@]} lines for $n_total commands (exit $rc; stderr: $(tail -n 2 "$WORK/client.err" | tr '\n' ' '))")
    fi
    if [ "$rc" -ne 0 ]; then
        n_bad=$((n_bad + 1))
        FAILS+=("$key: client exit status $rc")
    fi
    if [ "$server_rc" -ne 0 ]; then
        n_bad=$((n_bad + 1))
        FAILS+=("$key: server exit status $server_rc on SIGTERM (expected 0)")
    fi
    if [ "$(cat "$WORK/server.out")" != READY ]; then
        n_bad=$((n_bad + 1))
        FAILS+=("$key: server stdout was not exactly READY")
    fi
    if [ "$n_bad" -eq 0 ]; then
        RESULT[$key]="pass $n_total/$n_total"
    else
        RESULT[$key]="FAIL $n_bad/$n_total"
    fi
}

# ---- usage errors exit 2 ----------------------------------------------------
USAGE_OK=0
USAGE_TOTAL=0
check_usage() { # check_usage LABEL CMD...
    shift
    USAGE_TOTAL=$((USAGE_TOTAL + 1))
    "$@" </dev/null >/dev/null 2>&1
    local rc=$?
    if [ "$rc" -eq 2 ]; then
        USAGE_OK=$((USAGE_OK + 1))
    else
        FAILS+=("usage: '$*' exited $rc (expected 2)")
    fi
}
check_usage_all() {
    check_usage libmodbus_server "$LIB_SERVER" --bogus
    check_usage libmodbus_server "$LIB_SERVER" --tcp 99999
    check_usage libmodbus_server "$LIB_SERVER" --rtu /dev/null --parity X
    check_usage libmodbus_client "$LIB_CLIENT" --tcp 127.0.0.1:1 bench
    check_usage libmodbus_client "$LIB_CLIENT" --tcp nohostport script
    check_usage pymodbus_server "$PYTHON" "$PEERS/pymodbus_server.py" --unit 0 --tcp 1502
    check_usage pymodbus_client "$PYTHON" "$PEERS/pymodbus_client.py" --tcp 127.0.0.1:1 script --count 3
    check_usage tokio-modbus-peer "$TOKIO" server --tcp 1502 --unit 300
    check_usage tokio-modbus-peer "$TOKIO" client --tcp 127.0.0.1:1 bench
    check_usage tokio-modbus-peer "$TOKIO" frobnicate
}

# ---- main ---------------------------------------------------------------------
START=$SECONDS
check_usage_all
for transport in "${TRANSPORTS[@]}"; do
    for server in "${SERVERS[@]}"; do
        for client in "${CLIENTS[@]}"; do
            # shellcheck disable=SC2254 # ONLY is a glob on purpose
            case "$server/$client/$transport" in ${ONLY:-*}) ;; *)
                RESULT[$server/$client/$transport]="-"
                continue
                ;;
            esac
            run_pair "$server" "$client" "$transport"
            printf 'selfcheck: %-9s server  %-9s client  %-3s  %s\n' \
                "$server" "$client" "$transport" "${RESULT[$server/$client/$transport]}" >&2
        done
    done
done

echo
for transport in "${TRANSPORTS[@]}"; do
    printf '%-4s %-18s' "$transport" "server \\ client"
    for client in "${CLIENTS[@]}"; do printf '%-14s' "$client"; done
    echo
    for server in "${SERVERS[@]}"; do
        printf '     %-18s' "$server"
        for client in "${CLIENTS[@]}"; do printf '%-14s' "${RESULT[$server/$client/$transport]}"; done
        echo
    done
    echo
done
echo "usage errors exit 2: $USAGE_OK/$USAGE_TOTAL"
if [ "${#NOTES[@]}" -gt 0 ]; then
    echo
    echo "known peer quirks expected by this check:"
    printf '  - %s\n' "${NOTES[@]}" | sort -u
fi
echo
if [ "${#FAILS[@]}" -gt 0 ]; then
    echo "FAILURES:"
    printf '  - %s\n' "${FAILS[@]}"
    echo "selfcheck: FAIL ($((SECONDS - START)) s)"
    exit 1
fi
echo "selfcheck: all passed ($((SECONDS - START)) s)"
exit 0
