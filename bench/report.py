#!/usr/bin/env python3
"""bench/report.py - the arithmetic behind bench/peers.sh (Python standard library only).

    report.py sleep-overshoot --ms 10 --samples 100
        How late a 10 ms sleep wakes on this machine (median, microseconds): mbpoll sleeps
        its poll rate after every poll, and that time is taken off its polls.
    report.py mbpoll --out F --err F --times F --quantity Q --poll-ms 10 --overshoot-us U
        mbpoll's output turned into the peer fixtures' bench object (see bench/README.md).
    report.py report --results results.jsonl --markdown RESULTS.md --plot results.svg ...
        Medians, the share of the theoretical rate, the goals and their ratios; the tables on
        stdout and in RESULTS.md, the plot through gnuplot.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict

REQUEST_CHARS = 8  # FC03 request: unit, fc, address, quantity, CRC
RESPONSE_CHARS = 25  # FC03 response for 10 registers: unit, fc, count, 20 data bytes, CRC
CLIENTS = ["ferrobus", "libmodbus", "pymodbus", "tokio", "mbpoll"]
SERVERS = ["ferrobus", "libmodbus", "pymodbus", "tokio"]
PEER_NAMES = {
    "ferrobus": "ferrobus",
    "libmodbus": "libmodbus",
    "pymodbus": "pymodbus",
    "tokio": "tokio-modbus",
    "mbpoll": "mbpoll",
}
# The paced pairs in table order; the last is the instrument's floor (no silent intervals kept
# on either side, so its loss against the wire time is the ptys' and the line's latency).
FLOOR = ("libmodbus", "libmodbus")
PACED_ORDER = [(c, "ferrobus") for c in CLIENTS] + [("ferrobus", s) for s in SERVERS[1:]] + [FLOOR]
GOAL_SHARE = 0.98
GOAL_SPEEDUP = 1.3
GOAL_CPU = 0.6


# ---- sleep-overshoot and mbpoll -------------------------------------------------------------
def sleep_overshoot(args: argparse.Namespace) -> int:
    late = []
    for _ in range(args.samples):
        start = time.monotonic_ns()
        time.sleep(args.ms / 1000)
        late.append(time.monotonic_ns() - start - args.ms * 1_000_000)
    print(round(statistics.median(late) / 1000))
    return 0


def mbpoll(args: argparse.Namespace) -> int:
    """Completed polls are those that printed their last register; failures go to stderr."""
    with open(args.out, encoding="utf-8", errors="replace") as f:
        done = sum(1 for line in f if line.startswith(f"[{args.quantity}]:"))
    with open(args.err, encoding="utf-8", errors="replace") as f:
        errors = sum(1 for line in f if "failed" in line)
    with open(args.times, encoding="utf-8") as f:
        real, user, system = (float(x) for x in f.read().split()[-3:])
    polls = done + errors
    # Wall time of the polling: mbpoll waits 20 ms after opening the port before the first.
    seconds = max(real - args.connect_ms / 1000, 1e-9)
    period = seconds / polls if polls else 0.0
    sleep = args.poll_ms / 1000 + args.overshoot_us / 1e6
    own = period - sleep
    tps = 1 / own if polls and own > 0 else 0.0
    print(
        json.dumps(
            {
                "transactions": polls,
                "errors": errors,
                "seconds": round(seconds, 6),
                "tps": round(tps, 1),
                "p50_us": None,
                "p99_us": None,
                "user_s": user,
                "sys_s": system,
                "derived": True,
                "tps_with_sleep": round(polls / seconds, 1),
                "period_us": round(period * 1e6, 1),
            },
            separators=(",", ":"),
        )
    )
    return 0


# ---- the report -------------------------------------------------------------------------------
def theoretical_tps(baud: int, parity: str) -> float:
    """(8 + 25) characters plus two t3.5 per transaction; 11-bit characters for 8E1, 10 for 8N1;
    t3.5 is 3.5 characters up to 19200 baud and 1.75 ms above."""
    bits = 11 if parity in ("E", "O") else 10
    char = bits / baud
    t35 = 3.5 * char if baud <= 19200 else 0.00175
    return 1 / ((REQUEST_CHARS + RESPONSE_CHARS) * char + 2 * t35)


def median(values):
    values = [v for v in values if v is not None]
    return statistics.median(values) if values else None


class Pair:
    """Every run of one (mode, line, client, server)."""

    def __init__(self, records):
        first = records[0]
        self.mode, self.line = first["mode"], first["line"]
        self.baud, self.parity = first["baud"], first["parity"]
        self.client, self.server = first["client"], first["server"]
        self.runs = len(records)
        benches = [r["bench"] for r in records]
        self.derived = any(b.get("derived") for b in benches)
        self.transactions = sum(b["transactions"] for b in benches)
        self.errors = sum(b["errors"] for b in benches)
        # The printed tps is rounded to 0.1 (2 % of a 9600-baud rate): recompute it.
        rates = [b["tps"] if b.get("derived") or not b["seconds"] else b["transactions"] / b["seconds"] for b in benches]
        self.tps = median(rates)
        self.tps_runs = rates
        self.p50_us = median(b.get("p50_us") for b in benches)
        self.p99_us = median(b.get("p99_us") for b in benches)
        self.master_cpu_us = median(
            (b["user_s"] + b["sys_s"]) / b["transactions"] * 1e6 if b["transactions"] else None for b in benches
        )
        self.slave_cpu_us = median(
            r["server_cpu_s"] / r["bench"]["transactions"] * 1e6 if r["bench"]["transactions"] else None
            for r in records
        )
        self.sim_late_us = median(r["sim_late_us"][0] if r.get("sim_late_us") else None for r in records)
        self.master_gaps = self.slave_gaps = None
        self.frames = None
        stats = [r["line_stats"] for r in records if r.get("line_stats")]
        if stats:
            # Endpoint 0 is the server's pty, endpoint 1 the client's (peers.sh opens them so).
            self.slave_gaps = sum(s["endpoints"][0]["gap_violations"] for s in stats)
            self.master_gaps = sum(s["endpoints"][1]["gap_violations"] for s in stats)
            self.frames = sum(s["frames"] for s in stats)
        self.theory = theoretical_tps(self.baud, self.parity) if self.mode == "paced" else None

    @property
    def share(self):
        return self.tps / self.theory if self.theory and self.tps else None

    @property
    def name(self):
        return f"{PEER_NAMES[self.client]} → {PEER_NAMES[self.server]}"


def load(path):
    groups = defaultdict(list)
    with open(path, encoding="utf-8") as f:
        for line in f:
            if line.strip():
                r = json.loads(line)
                groups[(r["mode"], r["line"], r["client"], r["server"])].append(r)
    return {k: Pair(v) for k, v in groups.items()}


def fmt(value, spec="{:.0f}", missing="–"):
    return missing if value is None else spec.format(value)


def table(header, rows):
    out = ["| " + " | ".join(header) + " |", "|" + "|".join("---:" if i else "---" for i in range(len(header))) + "|"]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def ratio_cell(value, goal, at_least=True):
    if value is None:
        return "–"
    ok = value >= goal if at_least else value <= goal
    return f"{value:.2f}× {'✓' if ok else '✗'}"


def paced_section(pairs):
    lines = []
    configs = sorted({(p.line, p.baud, p.parity) for p in pairs.values() if p.mode == "paced"}, key=lambda c: c[1])
    for line, baud, parity in configs:
        theory = theoretical_tps(baud, parity)
        per_tx = 1e3 / theory
        lines.append(
            f"### Paced virtual line, {line.replace('-', ' ')}: theoretical {theory:.2f} transactions/s "
            f"({per_tx:.3f} ms per transaction)\n"
        )
        rows = []
        for c, s in PACED_ORDER:
            p = pairs.get(("paced", line, c, s))
            if not p:
                continue
            rows.append(
                [
                    p.name + (" ¹" if p.derived else "") + (" ³" if (c, s) == FLOOR else ""),
                    fmt(p.tps, "{:.2f}"),
                    fmt(p.share * 100 if p.share else None, "{:.1f} %"),
                    fmt(p.p50_us / 1e3 if p.p50_us else None, "{:.2f}"),
                    fmt(p.p99_us / 1e3 if p.p99_us else None, "{:.2f}"),
                    f"{p.master_gaps} / {p.transactions}",
                    f"{p.slave_gaps} / {p.transactions}",
                    fmt(p.sim_late_us, "{:.0f}"),
                    p.errors,
                    p.runs,
                ]
            )
        lines.append(
            table(
                [
                    "master → slave",
                    "transactions/s",
                    "of theoretical",
                    "p50 ms",
                    "p99 ms",
                    "gaps broken by master",
                    "by slave",
                    "sim reply late, p50 µs ²",
                    "errors",
                    "runs",
                ],
                rows,
            )
        )
        lines.append("")
    return "\n".join(lines)


def unpaced_section(pairs):
    lines = ["### Unpaced pty pair (socat, no line; ferrobus with --t35 0ms)\n"]
    rows = []
    for s in SERVERS:
        for c in CLIENTS:
            p = pairs.get(("unpaced", "pty", c, s))
            if not p:
                continue
            rows.append(
                [
                    p.name + (" ¹" if p.derived else ""),
                    fmt(p.tps, "{:.0f}"),
                    " / ".join(f"{t:.0f}" for t in p.tps_runs),
                    fmt(p.p50_us, "{:.0f}"),
                    fmt(p.p99_us, "{:.0f}"),
                    fmt(p.master_cpu_us, "{:.1f}"),
                    fmt(p.slave_cpu_us, "{:.1f}"),
                    p.errors,
                    p.transactions,
                ]
            )
    lines.append(
        table(
            [
                "master → slave",
                "transactions/s (median)",
                "each run",
                "p50 µs",
                "p99 µs",
                "master CPU µs/tx",
                "slave CPU µs/tx",
                "errors",
                "transactions",
            ],
            rows,
        )
    )
    lines.append("")
    # The same rates as a matrix, easier to compare along a row or a column.
    matrix = []
    for c in CLIENTS:
        row = [PEER_NAMES[c]]
        for s in SERVERS:
            p = pairs.get(("unpaced", "pty", c, s))
            row.append(fmt(p.tps if p else None, "{:.0f}"))
        if any(cell != "–" for cell in row[1:]):
            matrix.append(row)
    lines.append("Transactions/s, client (row) against server (column):\n")
    lines.append(table(["client \\ server"] + [PEER_NAMES[s] for s in SERVERS], matrix))
    lines.append("")
    return "\n".join(lines)


def goals_section(pairs):
    out = ["## Goals\n"]
    # 1. Paced: ferrobus ↔ ferrobus at >= 98 % of the theoretical rate, every gap kept.
    rows = []
    for (mode, line, c, s), p in sorted(pairs.items(), key=lambda kv: kv[1].baud):
        if mode == "paced" and c == "ferrobus" and s == "ferrobus":
            kept = p.master_gaps == 0 and p.slave_gaps == 0
            ok = p.share is not None and p.share >= GOAL_SHARE and kept
            bits = 11 if p.parity in ("E", "O") else 10
            char = bits / p.baud
            wire = (REQUEST_CHARS + RESPONSE_CHARS) * char
            floor = pairs.get(("paced", line) + FLOOR)
            floor_us = (1 / floor.tps - wire) * 1e6 if floor and floor.tps else None
            own_us = (1 / p.tps - 1 / p.theory) * 1e6 if p.tps else None
            reachable = 1 / (1 / p.theory + floor_us / 1e6) if floor_us is not None else None
            rows.append(
                [
                    line.replace("-", " "),
                    fmt(p.share * 100 if p.share else None, "{:.1f} %"),
                    f"{p.master_gaps} / {p.slave_gaps}",
                    "met ✓" if ok else "missed ✗",
                    fmt(own_us, "{:.0f}"),
                    fmt(floor_us, "{:.0f}"),
                    own_cell(own_us, floor_us),
                    fmt(p.tps / reachable * 100 if reachable else None, "{:.1f} %"),
                ]
            )
    out.append("**Paced: ferrobus client + ferrobus sim ≥ 98 % of the theoretical rate, every gap kept.**\n")
    out.append(
        table(
            [
                "line",
                "share of theoretical",
                "gaps broken (master / slave)",
                "goal",
                "µs lost per transaction",
                "of which the line's floor ³",
                "ferrobus's own",
                "share of theoretical + floor",
            ],
            rows,
        )
    )
    out.append("")

    # 2 and 3. Unpaced, each role: ferrobus against the peers in the same role, with the same
    # other side.
    out += role_goal_table(pairs, "client")
    out += role_goal_table(pairs, "server")
    return "\n".join(out)


def own_cell(own_us, floor_us):
    """What ferrobus itself loses per transaction: its loss less the line's floor, or a note
    when the floor pair's runs were the slower ones (the machine's noise, not a figure)."""
    if own_us is None or floor_us is None:
        return fmt(None, "{:.0f}")
    if own_us < floor_us:
        return "— (the floor's runs were slower: noise)"
    return fmt(own_us - floor_us, "{:.0f}")


def role_goal_table(pairs, role):
    """The unpaced goal table for ferrobus as `role` ("client" or "server"): its rate against
    each peer in that role with the same other side, and its CPU beside libmodbus's."""
    peers = ["libmodbus", "pymodbus", "tokio"]
    client = role == "client"
    rows = []
    for other in SERVERS if client else CLIENTS:
        key = (lambda us: ("unpaced", "pty", us, other)) if client else (lambda us: ("unpaced", "pty", other, us))
        f = pairs.get(key("ferrobus"))
        others = {p: pairs.get(key(p)) for p in peers}
        if not f or not any(others.values()):
            continue
        cpu = (lambda p: p.master_cpu_us) if client else (lambda p: p.slave_cpu_us)
        best = max((p.tps for p in others.values() if p and p.tps), default=None)
        lib = others.get("libmodbus")
        row = [f"{'against' if client else 'for'} {PEER_NAMES[other]}", fmt(f.tps, "{:.0f}")]
        row += [fmt(f.tps / others[p].tps if others[p] and others[p].tps else None, "{:.2f}×") for p in peers]
        row.append(ratio_cell(f.tps / best if best else None, GOAL_SPEEDUP))
        row.append(fmt(cpu(f), "{:.1f}") + " / " + fmt(cpu(lib) if lib else None, "{:.1f}"))
        row.append(
            ratio_cell(cpu(f) / cpu(lib) if lib and cpu(lib) and cpu(f) else None, GOAL_CPU, at_least=False)
        )
        rows.append(row)
    if client:
        title = ("**Unpaced, client role: ferrobus client ≥ 1.3× the fastest peer client against the same "
                 "server, CPU per transaction ≤ 0.6× libmodbus's.**\n")
        head = ["server", "ferrobus tx/s"]
    else:
        title = ("**Unpaced, server role: ferrobus sim ≥ 1.3× the fastest peer server for the same client, "
                 "CPU per transaction ≤ 0.6× libmodbus's.**\n")
        head = ["client", "ferrobus sim tx/s"]
    head += ["÷ libmodbus", "÷ pymodbus", "÷ tokio-modbus", "÷ fastest peer (goal ≥ 1.3)",
             "CPU µs/tx ferrobus / libmodbus", "CPU ratio (goal ≤ 0.6)"]
    return [title, table(head, rows), ""]


def run(cmd, cwd=None):
    try:
        return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def versions(args):
    root = args.root
    lock = os.path.join(root, "tests/peers/tokio-modbus-peer/Cargo.lock")
    tokio_modbus = "?"
    if os.path.exists(lock):
        text = open(lock, encoding="utf-8").read()
        m = re.search(r'name = "tokio-modbus"\nversion = "([^"]+)"', text)
        tokio_modbus = m.group(1) if m else "?"
    tokio = "?"
    main_lock = os.path.join(root, "Cargo.lock")
    if os.path.exists(main_lock):
        m = re.search(r'name = "tokio"\nversion = "([^"]+)"', open(main_lock, encoding="utf-8").read())
        tokio = m.group(1) if m else "?"
    rev = run(["git", "rev-parse", "--short", "HEAD"], cwd=root)
    # The files this report writes are changed by the run itself; they are not local changes.
    outputs = [os.path.relpath(os.path.abspath(f), root) for f in (args.results, args.markdown, args.plot) if f]
    outputs = [f":(exclude){f}" for f in outputs if not f.startswith("..")]
    dirty = run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".", *outputs], cwd=root)
    pymodbus = run([sys.executable, "-c", "import pymodbus; print(pymodbus.__version__)"])
    pyserial = run([sys.executable, "-c", "import serial; print(serial.__version__)"])
    libmodbus = run(["pkg-config", "--modversion", "libmodbus"]) or run(
        ["dpkg-query", "-W", "-f=${Version}", "libmodbus5"]
    )
    mbpoll = run(["dpkg-query", "-W", "-f=${Version}", "mbpoll"]) or run(["mbpoll", "-V"])
    socat = next((l for l in run(["socat", "-V"]).splitlines() if "socat version" in l), "?")
    return [
        ("ferrobus", f"{run([args.ferrobus, '--version'])} (git {rev}{' + local changes' if dirty else ''})"),
        ("rustc", run(["rustc", "--version"])),
        ("tokio (ferrobus)", tokio),
        ("libmodbus", libmodbus),
        ("pymodbus", f"{pymodbus} (pyserial {pyserial}, {run([sys.executable, '--version'])})"),
        ("tokio-modbus", f"{tokio_modbus} (tests/peers/tokio-modbus-peer, built with the same rustc)"),
        ("mbpoll", mbpoll),
        ("socat", socat.replace("socat by Gerhard Rieger and contributors - see www.dest-unreach.org", "").strip()),
        ("gnuplot", run(["gnuplot", "--version"])),
    ]


def machine():
    model = next(
        (l.split(":", 1)[1].strip() for l in run(["lscpu"]).splitlines() if l.startswith("Model name")), "?"
    )
    load = open("/proc/loadavg").read().split()[:3] if os.path.exists("/proc/loadavg") else ["?"]
    return [
        ("date", datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")),
        ("CPUs (nproc)", run(["nproc"])),
        ("CPU model (lscpu)", model),
        ("kernel", run(["uname", "-r"])),
        ("load average at the end", " ".join(load)),
    ]


def plot(pairs, path):
    """Two panels: paced share of the theoretical rate; unpaced rate per client and server."""
    with tempfile.TemporaryDirectory() as tmp:
        paced = os.path.join(tmp, "paced.dat")
        configs = sorted({(p.line, p.baud) for p in pairs.values() if p.mode == "paced"}, key=lambda c: c[1])
        order = PACED_ORDER
        with open(paced, "w", encoding="utf-8") as f:
            f.write("pair " + " ".join(f'"{line}"' for line, _ in configs) + "\n")
            for c, s in order:
                cells = []
                for line, _ in configs:
                    p = pairs.get(("paced", line, c, s))
                    cells.append(f"{p.share * 100:.2f}" if p and p.share else "NaN")
                if any(x != "NaN" for x in cells):
                    label = f"{PEER_NAMES[c]}→{PEER_NAMES[s]}".replace("-modbus", "")
                    f.write(f'"{label}" ' + " ".join(cells) + "\n")
        unpaced = os.path.join(tmp, "unpaced.dat")
        with open(unpaced, "w", encoding="utf-8") as f:
            f.write("client " + " ".join(f'"{PEER_NAMES[s]} sim"' if s == "ferrobus" else f'"{PEER_NAMES[s]}"' for s in SERVERS) + "\n")
            for c in CLIENTS[:-1]:
                cells = []
                for s in SERVERS:
                    p = pairs.get(("unpaced", "pty", c, s))
                    cells.append(f"{p.tps:.1f}" if p and p.tps else "NaN")
                f.write(f'"{PEER_NAMES[c]}" ' + " ".join(cells) + "\n")
        n_paced = len(configs)
        if path.endswith(".png"):
            terminal = 'set terminal pngcairo size 1100,900 font "sans,10" background rgb "white"'
        else:
            terminal = 'set terminal svg size 1100,900 dynamic font "sans,11" background rgb "white"'
        script = f"""
{terminal}
set output "{path}"
set multiplot layout 2,1
set style data histograms
set style histogram clustered gap 1
set style fill solid 0.85 border -1
set grid ytics
set key outside right top
set xtics rotate by -25
set title "Paced virtual line: share of the theoretical rate (FC03, 10 registers; above 100 % = silent intervals skipped)"
set ylabel "% of theoretical"
set yrange [0:*]
plot for [i=2:{n_paced + 1}] "{paced}" using i:xtic(1) title columnheader(i), 98 with lines lw 2 dt 2 lc rgb "red" title "goal 98 %"
set title "Unpaced pty pair: transactions/s, client (group) against server (bar)"
set ylabel "transactions/s"
set yrange [0:*]
set xtics norotate
plot for [i=2:{len(SERVERS) + 1}] "{unpaced}" using i:xtic(1) title columnheader(i)
unset multiplot
"""
        result = subprocess.run(["gnuplot"], input=script, capture_output=True, text=True)
        if result.returncode != 0:
            sys.stderr.write(f"report.py: gnuplot failed:\n{result.stderr}")
            return False
    return True


def report(args: argparse.Namespace) -> int:
    pairs = load(args.results)
    body = []
    body.append("# ferrobus beside libmodbus, pymodbus, tokio-modbus and mbpoll\n")
    body.append(
        "Written by `bench/peers.sh` (see `bench/README.md` for the method); medians of the runs of each pair. "
        "The machine is shared and noisy: compare ratios measured in the same run, not absolute figures "
        "across machines.\n"
    )
    if args.quick == "1":
        body.append("**QUICK=1 smoke run: a tenth of the counts, one run per pair. Not a measurement.**\n")
    body.append("## Machine and versions\n")
    body.append(table(["", ""], machine() + versions(args)))
    body.append(
        f"\nThe whole script ran in {args.elapsed} s; runs per pair (paced / unpaced): {args.reps}. "
        f"A 10 ms sleep overshot by {args.overshoot_us} µs here (taken off mbpoll's polls).\n"
    )
    body.append(goals_section(pairs))
    body.append("## Results\n")
    body.append(paced_section(pairs))
    body.append(unpaced_section(pairs))
    body.append(
        "¹ mbpoll has no bench mode: it polls with its shortest poll rate (`-l 10`, a 10 ms sleep after each "
        "poll) for a fixed time; transactions/s is derived from its polls with the sleep taken away "
        "(bench/README.md). It has no latency figures.\n\n"
        "A share above 100 % is not faster than the wire: it is the silent intervals that side did not "
        "keep (see the gaps columns). mbpoll's derived time per transaction leaves out the t3.5 before "
        "its next request, which its 10 ms sleep covers, so it can pass 100 % without breaking a gap.\n\n"
        "² How late ferrobus sim began to write its replies after they were due (t3.5 after the request "
        "reached it), median of its own count: the timer's and the scheduler's share of the lost rate.\n\n"
        "³ The instrument's floor: libmodbus client and server keep no silent interval, so the time "
        "a libmodbus → libmodbus transaction takes beyond the wire time of its 33 characters is the "
        "latency of the ptys and of the line process (four pty crossings per transaction), which every "
        "pair on the line pays too. \"ferrobus's own\" is what ferrobus ↔ ferrobus loses beyond it: "
        "how late its timers wake.\n\n"
        "Gaps broken: frames the master (or slave) began less than t3.5 after the line was last busy, as "
        "counted by `ferrobus line`, over all the pair's transactions. CPU per transaction: user + system "
        "time of the master as its bench printed it (the whole process, start-up included), divided by its "
        "transactions; for the slave, the CPU time its threads used during the client's run "
        "(/proc/PID/task/*/schedstat) divided by the transactions.\n"
    )
    if args.plot and plot(pairs, args.plot):
        body.append(f"![the plot]({os.path.basename(args.plot)})\n")
    text = "\n".join(body)
    if args.markdown:
        with open(args.markdown, "w", encoding="utf-8") as f:
            f.write(text)
    print(text)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("sleep-overshoot")
    p.add_argument("--ms", type=float, default=10)
    p.add_argument("--samples", type=int, default=100)
    p = sub.add_parser("mbpoll")
    p.add_argument("--out", required=True)
    p.add_argument("--err", required=True)
    p.add_argument("--times", required=True)
    p.add_argument("--quantity", type=int, required=True)
    p.add_argument("--poll-ms", type=float, default=10)
    p.add_argument("--overshoot-us", type=float, default=0)
    p.add_argument("--connect-ms", type=float, default=20)
    p = sub.add_parser("report")
    p.add_argument("--results", required=True)
    p.add_argument("--markdown")
    p.add_argument("--plot")
    p.add_argument("--elapsed", default="?")
    p.add_argument("--ferrobus", default="ferrobus")
    p.add_argument("--root", default=".")
    p.add_argument("--overshoot-us", default="?")
    p.add_argument("--reps", default="?")
    p.add_argument("--quick", default="0")
    args = parser.parse_args()
    return {"sleep-overshoot": sleep_overshoot, "mbpoll": mbpoll, "report": report}[args.command](args)


if __name__ == "__main__":
    sys.exit(main())
