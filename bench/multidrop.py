#!/usr/bin/env python3
"""bench/multidrop.py - what one slow or dead unit costs the other units of a multidrop line.

Two simulated units share one RTU line behind `ferrobus gateway` (per-unit backoff off, so
that the bad unit costs what it costs on every request), in two shapes:

  bus      `ferrobus line` (a virtual RS-485 bus with character timing, 19200 8N1) with the
           gateway and two `ferrobus sim`s, one unit each, on three drops: independent devices,
           whose replies may collide on the wire;
  one-sim  one `ferrobus sim --pty` serving both units: one responder, busy with one request
           at a time (a multi-unit device).

Client A reads unit 1 in a closed loop; client B reads unit 2 in a closed loop. Unit 1 is,
per scenario:

  silent   never answers: each of A's reads times out (after the first late window, the unit
           is known dead and its timeouts owe nothing);
  lossy    drops every other reply at random (drop=50%): each drop is a timeout whose reply is
           owed for the late window, since the unit is alive;
  slow     answers every read LATE ms after it (past the timeout): each times out, and its
           reply comes late;
  healthy  answers at once (the reference).

For each binary given (FERROBUS, and OLD to compare with, e.g. one built from an earlier
commit) and scenario, it runs SECONDS and prints unit 2's reads per second, their latency
p50/p99, how many came back wrong (a value not unit 2's), unit 1's outcomes, and the ratio of
each binary's unit-2 rate to the healthy reference of the same binary.

Environment: FERROBUS (default target/release/ferrobus), OLD (optional), SECONDS (10),
TIMEOUT (the gateway's --timeout, default 200ms), LATE (ms, default 350), PYTHON.
Prints one JSON record per run on stdout and the table on stderr. Installs nothing; every
process it starts is stopped on exit.
"""

import json
import os
import socket
import statistics
import struct
import subprocess
import sys
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SECONDS = float(os.environ.get("SECONDS", "10"))
TIMEOUT = os.environ.get("TIMEOUT", "200ms")
LATE = int(os.environ.get("LATE", "350"))
# What unit 2's holding register 0 holds, written before each run; unit 1's holds another.
UNIT2_VALUE = 0x2222
UNIT1_VALUE = 0x1111


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Client:
    """A Modbus/TCP client with one request outstanding."""

    def __init__(self, addr):
        self.sock = socket.create_connection(addr, timeout=30)
        self.tid = 0

    def ask(self, unit, pdu):
        self.tid = (self.tid + 1) & 0xFFFF
        self.sock.sendall(struct.pack(">HHHB", self.tid, 0, len(pdu) + 1, unit) + pdu)
        head = self._exactly(7)
        tid, _, length, _ = struct.unpack(">HHHB", head)
        body = self._exactly(length - 1)
        if tid != self.tid:
            raise RuntimeError(f"reply under tid {tid}, asked {self.tid}")
        return body

    def _exactly(self, n):
        data = b""
        while len(data) < n:
            chunk = self.sock.recv(n - len(data))
            if not chunk:
                raise RuntimeError("the gateway closed the connection")
            data += chunk
        return data


def read_register(unit):
    return bytes([0x03, 0x00, 0x00, 0x00, 0x01])


def first_line(proc, what):
    line = proc.stdout.readline().strip()
    if not line.startswith("/"):
        proc.kill()
        sys.exit(f"multidrop.py: {what} printed {line!r}, not a pty")
    return line


def start(binary, shape, scenario):
    """The line, the sims and the gateway; returns (processes, gateway address)."""
    fault = {"silent": ["--fault", "1:silent"], "lossy": ["--fault", "1:drop=50%"],
             "slow": ["--fault", f"1:delay={LATE}ms"]}.get(scenario, [])
    quiet = {"stdout": subprocess.PIPE, "stderr": subprocess.DEVNULL, "text": True}
    procs = []
    if shape == "one-sim":
        sim = subprocess.Popen([binary, "sim", "--pty", "--profile", "generic", "--unit", "1", "--unit", "2", *fault],
                               **quiet)
        procs.append(sim)
        path = first_line(sim, "the sim")
    else:
        line = subprocess.Popen([binary, "line", "--drops", "3", "--parity", "none"], **quiet)
        procs.append(line)
        path, *drops = [first_line(line, "the line") for _ in range(3)]
        for unit, drop in zip((1, 2), drops):
            faults = fault if unit == 1 else []
            procs.append(subprocess.Popen(
                [binary, "--port", drop, "--parity", "none", "--unit", str(unit), "sim", "--profile", "generic",
                 *faults], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        time.sleep(1)  # the sims open their drops
    port = free_port()
    gateway = subprocess.Popen(
        [binary, "--port", path, "--parity", "none", "--timeout", TIMEOUT, "gateway",
         "--listen", f"127.0.0.1:{port}", "--backoff-after", "0"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    procs.insert(0, gateway)
    for text in gateway.stderr:
        if text.startswith("gateway: listening on"):
            break
    else:
        for p in procs:
            p.kill()
        sys.exit("multidrop.py: the gateway did not start")
    threading.Thread(target=lambda: gateway.stderr.read(), daemon=True).start()
    return procs, ("127.0.0.1", port)


def run(binary, label, shape, scenario):
    procs, addr = start(binary, shape, scenario)
    try:
        setup = Client(addr)
        for unit, value in ((2, UNIT2_VALUE), (1, UNIT1_VALUE)):
            # Unit 1 may not answer (silent, slow): its write is best effort.
            setup.ask(unit, struct.pack(">BHH", 0x06, 0, value))
        stop = time.monotonic() + SECONDS
        latencies, wrong, failed, unit1 = [], 0, 0, {"ok": 0, "exception": 0}

        def poll_unit1():
            a = Client(addr)
            while time.monotonic() < stop:
                reply = a.ask(1, read_register(1))
                unit1["exception" if reply[0] & 0x80 else "ok"] += 1

        bad = threading.Thread(target=poll_unit1, daemon=True)
        bad.start()
        b = Client(addr)
        while time.monotonic() < stop:
            began = time.monotonic()
            reply = b.ask(2, read_register(2))
            if reply[0] & 0x80:
                failed += 1
                continue
            latencies.append(time.monotonic() - began)
            if reply != struct.pack(">BBH", 0x03, 2, UNIT2_VALUE):
                wrong += 1
        bad.join(timeout=5)
        ms = sorted(x * 1000 for x in latencies)
        record = {
            "binary": label, "shape": shape, "scenario": scenario, "seconds": SECONDS, "timeout": TIMEOUT,
            "late_ms": LATE if scenario == "slow" else None,
            "unit2_reads": len(ms), "unit2_per_s": len(ms) / SECONDS,
            "unit2_p50_ms": statistics.median(ms) if ms else None,
            "unit2_p99_ms": ms[min(len(ms) - 1, int(len(ms) * 0.99))] if ms else None,
            "unit2_wrong": wrong, "unit2_exceptions": failed, "unit1_ok": unit1["ok"], "unit1_exceptions": unit1["exception"],
        }
        print(json.dumps(record), flush=True)
        return record
    finally:
        for p in procs:
            p.kill()
            p.wait()


def main():
    binaries = [("new", os.environ.get("FERROBUS", os.path.join(ROOT, "target/release/ferrobus")))]
    if os.environ.get("OLD"):
        binaries.append(("old", os.environ["OLD"]))
    for _, path in binaries:
        if not os.access(path, os.X_OK):
            sys.exit(f"multidrop.py: no ferrobus at {path} (cargo build --release -p ferrobus-cli, or FERROBUS=...)")
    records = []
    for shape in ("bus", "one-sim"):
        for scenario in ("healthy", "silent", "lossy", "slow"):
            for label, path in binaries:
                records.append(run(path, label, shape, scenario))
    reference = {(r["binary"], r["shape"]): r["unit2_per_s"] for r in records if r["scenario"] == "healthy"}
    out = sys.stderr
    print(f"\nunit 2's reads with unit 1 {', '.join(('healthy', 'silent', 'lossy', f'slow ({LATE} ms)'))}; "
          f"--timeout {TIMEOUT}, {SECONDS:g} s per run\n", file=out)
    print("| shape | binary | unit 1 | unit 2 reads/s | vs healthy | p50 ms | p99 ms | unit 2 wrong / exceptions "
          "| unit 1 ok / exceptions |", file=out)
    print("|---|---|---|---:|---:|---:|---:|---:|---:|", file=out)
    for r in records:
        healthy = reference.get((r["binary"], r["shape"]))
        ratio = r["unit2_per_s"] / healthy if healthy else float("nan")
        p50, p99 = (f"{r[k]:.1f}" if r[k] is not None else "-" for k in ("unit2_p50_ms", "unit2_p99_ms"))
        print(f"| {r['shape']} | {r['binary']} | {r['scenario']} | {r['unit2_per_s']:.1f} | {ratio:.2f} | "
              f"{p50} | {p99} | {r['unit2_wrong']} / {r['unit2_exceptions']} | "
              f"{r['unit1_ok']} / {r['unit1_exceptions']} |", file=out)


if __name__ == "__main__":
    main()
