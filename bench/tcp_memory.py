#!/usr/bin/env python3
"""What a Modbus/TCP connection costs `ferrobus sim --tcp` in memory, and whether it is given back.

Starts `ferrobus sim --profile generic --tcp 127.0.0.1:PORT` (the binary given, by default the
release build), reads its VmRSS from /proc idle, opens N connections (1,000 by default) that
each make one read and then stay idle, reads VmRSS again, closes them, waits until the sim's
process holds no more sockets than before, and reads VmRSS again; then all of it once more (a
second round shows whether what stayed is reused or lost). Prints a line of figures per round:
RSS idle, connected and after the close (KiB), the cost per connection ((connected - idle) / N)
and what stayed per connection after the close ((closed - idle) / N).

The clients are spread over 127.0.0.1-127.0.0.10 so that the sim's per-source limit
(--max-per-source, default 100) is not what is measured; the sim gets --max-connections N+100.
It targets the loopback only. Needs `ulimit -n` above 2 N (client and server sockets).
"""

import argparse
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def rss_kib(pid):
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError("no VmRSS")


def sockets(pid):
    """How many sockets the process holds."""
    n = 0
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}").startswith("socket:"):
                n += 1
        except OSError:
            pass
    return n


def settle(pid, done, what, limit=60.0):
    """Waits until `done()` holds (bounded: a failure after `limit` seconds, not a figure)."""
    deadline = time.monotonic() + limit
    while not done():
        if time.monotonic() > deadline:
            sys.exit(f"tcp_memory: {what} did not happen within {limit} s")
        time.sleep(0.05)
    time.sleep(0.5)  # the allocator's and the runtime's own settling, the same for every run


def read_holding(sock, tid):
    sock.sendall(struct.pack(">HHHBBHH", tid, 0, 6, 1, 3, 0, 2))
    reply = b""
    while len(reply) < 13:
        chunk = sock.recv(64)
        if not chunk:
            raise RuntimeError("closed")
        reply += chunk
    return reply


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ferrobus", default=str(ROOT / "target/release/ferrobus"))
    ap.add_argument("--connections", type=int, default=1000)
    ap.add_argument("--port", type=int, default=0, help="default: a free one")
    args = ap.parse_args()
    port = args.port
    if port == 0:
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
    n = args.connections
    sim = subprocess.Popen(
        [args.ferrobus, "sim", "--profile", "generic", "--tcp", f"127.0.0.1:{port}",
         "--max-connections", str(n + 100), "--idle-timeout", "0"],
        stderr=subprocess.PIPE, text=True)
    try:
        said = []
        while not (said and said[-1].startswith("sim: listening on")):
            line = sim.stderr.readline()
            if not line:
                sys.exit("tcp_memory: the sim exited:\n" + "".join(said))
            said.append(line)
        time.sleep(0.5)
        base_sockets = sockets(sim.pid)
        idle = rss_kib(sim.pid)
        rounds = []
        for _ in range(2):
            clients = []
            for i in range(n):
                s = socket.socket()
                s.bind((f"127.0.0.{1 + i % 10}", 0))
                s.connect(("127.0.0.1", port))
                read_holding(s, i & 0xFFFF)
                clients.append(s)
            settle(sim.pid, lambda: sockets(sim.pid) >= base_sockets + n, "every connection accepted")
            connected = rss_kib(sim.pid)
            for s in clients:
                s.close()
            settle(sim.pid, lambda: sockets(sim.pid) <= base_sockets, "every connection closed")
            rounds.append((connected, rss_kib(sim.pid)))
    finally:
        sim.terminate()
        sim.wait()
    for k, (connected, closed) in enumerate(rounds, 1):
        print(f"round {k}, {n} connections: RSS idle {idle} KiB, connected {connected} KiB, after the close "
              f"{closed} KiB; {(connected - idle) / n:.1f} KiB per connection, {(closed - idle) / n:.1f} KiB per "
              f"connection kept after the close")


if __name__ == "__main__":
    main()
