#!/usr/bin/env bash
# bench/mux.sh - `ferrobus gateway` as a Modbus/TCP multiplexer: many clients through the
# gateway to one server that serves one TCP connection at a time (tests/peers'
# libmodbus_server, the typical one-client device), against that server's own rate with one
# client straight to it.
#
# For each service time S in SERVICES (microseconds the server sleeps before each reply,
# libmodbus_server --service-us; 0 is raw loopback), REPS times, interleaved:
#   direct   bench/gateway_load.py with 1 closed-loop client straight to a fresh server;
#   libmodbus  `libmodbus_client --tcp ... bench` straight to a fresh server (a C client: a
#            second reference for the server's one-client rate);
#   gateway  CLIENTS (100) closed-loop clients (the same gateway_load.py) -> `ferrobus --tcp
#            127.0.0.1:PORT gateway --in-flight N` -> a fresh server, for each N in IN_FLIGHT. Each client writes its own block of 10
#            holding registers (client i at 10*i: 100 x 10 fits the peers' 1000) and reads it
#            back: a reply with the wrong tid, unit or values is a mismatch;
#   gateway_c  CLIENTS `libmodbus_client bench` processes at once through the gateway (each
#            reads 10 registers at 0, about half a run's worth at the direct rate; libmodbus
#            checks each reply's tid): the gateway under C clients, which cost less than the
#            Python ones; its rate is the sum of the clients' own rates, and its ratio is to
#            the libmodbus bench straight to the server.
# Then per S and N: the medians of the runs and ratio = gateway tps / direct tps (the median of the
# per-rep ratios, each rep's two runs taken back to back), client-side p50/p99, exceptions by
# code, lost connections, and the CPU per transaction of the gateway and of the server (from
# /proc/PID/task/*/schedstat while the window was open).
#
# Prints one JSON record per run on stdout, then the summary table (markdown) on stderr.
# bench/MUX.md's results are written by hand from one run, with the machine it ran on.
#
# Environment: FERROBUS=PATH (default target/release/ferrobus: cargo build --release -p
# ferrobus-cli), PEERS=DIR (target/peers), PYTHON (python3), SERVICES ("0 1000 5000"),
# REPS (3), SECONDS_PER_RUN (10), CLIENTS (100, at most 100), IN_FLIGHT ("1 8": the gateway's
# --in-flight, requests outstanding on the server's connection at once; 1 sends one at a time,
# as the one-client direct run does; the libmodbus server reads its connection in order, so
# more are answered in turn), RECORDS=FILE (also append the JSON records there), QUICK=1 (one
# rep of 3 s per run: a smoke run under a minute).
# Installs nothing; every process it starts is stopped on exit, Ctrl-C included.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FERROBUS="${FERROBUS:-$ROOT/target/release/ferrobus}"
PEERS="${PEERS:-$ROOT/target/peers}"
PYTHON="${PYTHON:-python3}"
SERVICES="${SERVICES:-0 1000 5000}"
REPS="${REPS:-3}"
RUN="${SECONDS_PER_RUN:-10}"
CLIENTS="${CLIENTS:-100}"
IN_FLIGHT="${IN_FLIGHT:-1 8}"
WARMUP=1
if [ "${QUICK:-0}" = 1 ]; then
    REPS=1
    RUN=3
    WARMUP=0.5
fi
SERVER="$PEERS/libmodbus_server"
CLIENT="$PEERS/libmodbus_client"
LOAD="$ROOT/bench/gateway_load.py"

die() { printf 'mux.sh: %s\n' "$*" >&2; exit 1; }
log() { printf 'mux.sh: %s\n' "$*" >&2; }

[ -x "$FERROBUS" ] || die "$FERROBUS is missing: cargo build --release -p ferrobus-cli (or set FERROBUS)"
for peer in "$SERVER" "$CLIENT"; do
    [ -x "$peer" ] || die "$peer is missing: run .ci/setup-peers.sh (it builds the peers into target/peers)"
done
"$SERVER" --help 2>/dev/null | grep -q -- --service-us ||
    die "$SERVER has no --service-us: it predates that option; rebuild it with .ci/setup-peers.sh"
command -v "$PYTHON" >/dev/null || die "$PYTHON is missing"
[[ "$CLIENTS" =~ ^[0-9]+$ ]] && [ "$CLIENTS" -ge 1 ] && [ "$CLIENTS" -le 100 ] ||
    die "CLIENTS must be 1..100 (each client has its own 10 registers of the server's 1000), not '$CLIENTS'"
[[ "$REPS" =~ ^[1-9][0-9]*$ ]] || die "REPS must be a positive number, not '$REPS'"
for s in $SERVICES; do
    [[ "$s" =~ ^[0-9]+$ ]] || die "SERVICES must be microsecond counts, not '$s'"
done
for n in $IN_FLIGHT; do
    [[ "$n" =~ ^[0-9]+$ ]] && [ "$n" -ge 1 ] && [ "$n" -le 16 ] || die "IN_FLIGHT must be counts 1..16, not '$n'"
done

ulimit -n 4096
WORK="$(mktemp -d)"
PIDS=()
# Stops every process this script started (TERM, then KILL after a second), removes $WORK.
cleanup() {
    local pid
    for pid in "${PIDS[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
    for pid in "${PIDS[@]}"; do
        for _ in $(seq 1 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.02; done
        kill -KILL "$pid" 2>/dev/null || true
        wait "$pid" 2>/dev/null || true
    done
    rm -rf "$WORK"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

wait_for() { # wait_for FILE TEXT PID
    for _ in $(seq 1 500); do
        grep -q "$2" "$1" 2>/dev/null && return 0
        kill -0 "$3" 2>/dev/null || break
        sleep 0.02
    done
    log "no '$2' in $1:"
    cat "$1" "$1.err" 2>/dev/null >&2 || true
    exit 1
}
stop() { kill -TERM "$1" 2>/dev/null || true; wait "$1" 2>/dev/null || true; }
free_port() { "$PYTHON" -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }

# start_server SERVICE_US: a fresh libmodbus server; sets SRV_PORT and SRV_PID.
start_server() {
    SRV_PORT="$(free_port)"
    "$SERVER" --tcp "$SRV_PORT" --service-us "$1" >"$WORK/srv" 2>"$WORK/srv.err" &
    SRV_PID=$!
    PIDS+=("$SRV_PID")
    wait_for "$WORK/srv" READY "$SRV_PID"
}

record() { # record JSON: to stdout and to $RECORDS; kept for the summary
    printf '%s\n' "$1" >>"$WORK/records.jsonl"
    [ -n "${RECORDS:-}" ] && printf '%s\n' "$1" >>"$RECORDS"
    printf '%s\n' "$1"
}

cpu_ns() { cat /proc/"$1"/task/*/schedstat 2>/dev/null | awk '{ s += $1 } END { printf "%d", s }'; }

# run_direct SERVICE_US REP: 1 closed-loop client straight to the server; sets DIRECT_TPS.
run_direct() {
    start_server "$1"
    local load
    load="$("$PYTHON" "$LOAD" --addr "127.0.0.1:$SRV_PORT" --clients 1 --seconds "$RUN" --warmup "$WARMUP" \
        --cpu "server=$SRV_PID")"
    stop "$SRV_PID"
    DIRECT_TPS="$(printf '%s' "$load" | "$PYTHON" -c 'import json,sys; print(int(json.load(sys.stdin)["tps"]))')"
    record "{\"mode\":\"direct\",\"service_us\":$1,\"rep\":$2,\"load\":$load}"
}

# run_libmodbus SERVICE_US REP: libmodbus's own client in bench mode, FC03 x 10 back to back,
# for about half a run.
run_libmodbus() {
    local count=$(( RUN * 1000000 / ($1 + 100) / 2 ))
    (( count > 100000 )) && count=100000
    (( count < 100 )) && count=100
    start_server "$1"
    local out
    out="$("$CLIENT" --tcp "127.0.0.1:$SRV_PORT" bench --count "$count" 2>"$WORK/client.err")" ||
        { cat "$WORK/client.err" >&2; die "libmodbus_client bench failed"; }
    stop "$SRV_PID"
    record "{\"mode\":\"libmodbus\",\"service_us\":$1,\"rep\":$2,\"bench\":$out}"
}

# start_gateway SERVICE_US IN_FLIGHT: a fresh server and the gateway in front of it; sets
# GW_PORT, GW_PID.
start_gateway() {
    start_server "$1"
    GW_PORT="$(free_port)"
    "$FERROBUS" --tcp "127.0.0.1:$SRV_PORT" gateway --listen "127.0.0.1:$GW_PORT" --queue $((CLIENTS + 16)) \
        --in-flight "$2" --max-connections 2000 --max-per-source 2000 >"$WORK/gw" 2>"$WORK/gw.err" &
    GW_PID=$!
    PIDS+=("$GW_PID")
    wait_for "$WORK/gw.err" "gateway: listening on" "$GW_PID"
}

# stop_gateway: stops the gateway and the server; sets WARNINGS (the gateway's WARN and ERROR
# lines: a lost line, timeouts) and FIRST_WARNING (the first, quotes removed).
stop_gateway() {
    stop "$GW_PID"
    stop "$SRV_PID"
    WARNINGS="$(grep -c -E 'WARN|ERROR' "$WORK/gw.err" || true)"
    FIRST_WARNING="$(grep -m1 -E 'WARN|ERROR' "$WORK/gw.err" | tr -d '"\\' | cut -c1-200 || true)"
}

# run_gateway SERVICE_US REP IN_FLIGHT: CLIENTS closed-loop clients through the gateway to
# the server.
run_gateway() {
    start_gateway "$1" "$3"
    local load
    load="$("$PYTHON" "$LOAD" --addr "127.0.0.1:$GW_PORT" --clients "$CLIENTS" --seconds "$RUN" --warmup "$WARMUP" \
        --cpu "gateway=$GW_PID" --cpu "server=$SRV_PID")"
    stop_gateway
    record "{\"mode\":\"gateway\",\"service_us\":$1,\"rep\":$2,\"in_flight\":$3,\"clients\":$CLIENTS,\"load\":$load,\"gateway_warnings\":${WARNINGS:-0},\"first_warning\":\"$FIRST_WARNING\"}"
}

# run_gateway_c SERVICE_US REP IN_FLIGHT: CLIENTS libmodbus_client bench processes through
# the gateway, all at once, each about half a run's worth of reads at the direct rate
# (DIRECT_TPS).
run_gateway_c() {
    local count=$(( DIRECT_TPS * RUN / 2 / CLIENTS ))
    (( count < 20 )) && count=20
    start_gateway "$1" "$3"
    local i pids=() cpu0 cpu1
    cpu0="$(cpu_ns "$GW_PID")"
    for i in $(seq 1 "$CLIENTS"); do
        "$CLIENT" --tcp "127.0.0.1:$GW_PORT" bench --count "$count" >"$WORK/c.$i" 2>"$WORK/c.$i.err" &
        pids+=($!)
        PIDS+=($!)
    done
    for i in "${pids[@]}"; do wait "$i" || true; done
    cpu1="$(cpu_ns "$GW_PID")"
    stop_gateway
    local benches
    benches="$(for i in $(seq 1 "$CLIENTS"); do cat "$WORK/c.$i"; done | paste -sd, -)"
    record "{\"mode\":\"gateway_c\",\"service_us\":$1,\"rep\":$2,\"in_flight\":$3,\"clients\":$CLIENTS,\"count\":$count,\"gateway_cpu_s\":$(( (cpu1 - cpu0) / 1000 ))e-6,\"benches\":[$benches],\"gateway_warnings\":${WARNINGS:-0},\"first_warning\":\"$FIRST_WARNING\"}"
    rm -f "$WORK"/c.*
}

log "machine: $(nproc) CPUs, load $(cut -d' ' -f1-3 /proc/loadavg); $("$FERROBUS" --version); services (us): $SERVICES; in flight: $IN_FLIGHT; $REPS x ${RUN} s; $CLIENTS clients"
: >"$WORK/records.jsonl"
for service in $SERVICES; do
    for rep in $(seq 1 "$REPS"); do
        log "service ${service} us, rep $rep/$REPS"
        run_direct "$service" "$rep"
        run_libmodbus "$service" "$rep"
        for n in $IN_FLIGHT; do
            run_gateway "$service" "$rep" "$n"
            run_gateway_c "$service" "$rep" "$n"
        done
    done
done

"$PYTHON" - "$WORK/records.jsonl" <<'EOF' >&2
import json, statistics, sys

records = [json.loads(line) for line in open(sys.argv[1])]
med = lambda xs: statistics.median(xs) if xs else None
fmt = lambda x, d=0: "–" if x is None else f"{x:,.{d}f}"
pct = lambda x: "–" if x is None else f"{x:.1%}" + (" ✓" if x >= 0.95 else " ✗")
clients = next((r["clients"] for r in records if r["mode"] == "gateway"), "?")
reps = max(r["rep"] for r in records)
failed = False
rows1, rows2 = [], []
for service, n in sorted({(r["service_us"], r.get("in_flight", 1)) for r in records if r["mode"] == "gateway"}):
    of = lambda mode: [r for r in records if r["mode"] == mode and r["service_us"] == service
                       and r.get("in_flight", n) == n]
    direct, lib, gw, gwc = of("direct"), of("libmodbus"), of("gateway"), of("gateway_c")
    # Each rep's gateway run against the same rep's direct run, taken just before it.
    py_tps = {r["rep"]: r["load"]["tps"] for r in direct}
    c_tps = {r["rep"]: r["bench"]["tps"] for r in lib}
    gwc_tps = {r["rep"]: sum(b["tps"] for b in r["benches"]) for r in gwc}
    ratio = med([g["load"]["tps"] / py_tps[g["rep"]] for g in gw if py_tps.get(g["rep"])])
    ratio_c = med([t / c_tps[rep] for rep, t in gwc_tps.items() if c_tps.get(rep)])
    cpu = lambda rs, name: med([r["load"]["cpu"][name]["us_per_transaction"] for r in rs
                                if r["load"].get("cpu", {}).get(name, {}).get("us_per_transaction") is not None])
    share = lambda rs, name: med([r["load"]["cpu"][name]["share"] for r in rs
                                  if r["load"].get("cpu", {}).get(name, {}).get("share") is not None])
    lat = lambda rs, key: med([r["load"][key] for r in rs if r["load"][key] is not None])
    exceptions = {}
    for r in direct + gw:
        for code, n in r["load"]["exceptions"].items():
            exceptions[code] = exceptions.get(code, 0) + n
    mismatches = sum(r["load"]["mismatches"] for r in direct + gw)
    lost = sum(r["load"]["lost"] for r in direct + gw)
    c_errors = sum(b["errors"] for r in gwc for b in r["benches"]) + sum(r["bench"]["errors"] for r in lib)
    c_missing = sum(r["clients"] - len(r["benches"]) for r in gwc)
    gwc_cpu = med([r["gateway_cpu_s"] * 1e6 / ok for r in gwc
                   if (ok := sum(b["transactions"] - b["errors"] for b in r["benches"])) > 0])
    warnings = sum(r["gateway_warnings"] for r in gw + gwc)
    failed |= mismatches > 0
    rows1.append(f"| {service / 1000:g} ms | {n} | {fmt(med(list(py_tps.values())))} "
                 f"| {fmt(med([r['load']['tps'] for r in gw]))} | {pct(ratio)} "
                 f"| {fmt(med(list(c_tps.values())))} | {fmt(med(list(gwc_tps.values())))} | {pct(ratio_c)} "
                 f"| {mismatches} | {json.dumps(exceptions, sort_keys=True) if exceptions else 0} | {lost} "
                 f"| {c_errors}{f' ({c_missing} no output)' if c_missing else ''} | {warnings} |")
    rows2.append(f"| {service / 1000:g} ms | {n} | {fmt(lat(direct, 'p50_ms'), 2)} / {fmt(lat(direct, 'p99_ms'), 2)} "
                 f"| {fmt(lat(gw, 'p50_ms'), 2)} / {fmt(lat(gw, 'p99_ms'), 2)} "
                 f"| {fmt(cpu(gw, 'gateway'), 1)} | {fmt(gwc_cpu, 1)} "
                 f"| {fmt(cpu(direct, 'server'), 1)} / {fmt(cpu(gw, 'server'), 1)} "
                 f"| {fmt(share(direct, 'clients'), 2)} / {fmt(share(gw, 'clients'), 2)} |")
print()
print(f"| service | in flight | direct, 1 client (tx/s) | gateway, {clients} clients (tx/s) | ratio "
      f"| libmodbus bench, 1 client (tx/s) | gateway, {clients} libmodbus clients (tx/s) | ratio "
      "| mismatches | exceptions | lost | libmodbus errors | gateway warnings |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
print("\n".join(rows1))
print()
print("| service | in flight | direct p50 / p99 (ms) | gateway p50 / p99 (ms) | gateway CPU (µs/tx) "
      "| gateway CPU, libmodbus clients (µs/tx) | server CPU direct / gateway (µs/tx) "
      "| load generator CPU direct / gateway (cores) |")
print("|---|---|---|---|---|---|---|---|")
print("\n".join(rows2))
print()
print(f"ratio: gateway tx/s over the one-client direct tx/s with the same client, the median of {reps} "
      "paired run(s); goal >= 95 % (✓ met, ✗ not), 0 mismatches")
if failed:
    print("mux.sh: MISMATCHES: a client got a reply that was not its own (see the records)")
    sys.exit(1)
EOF
