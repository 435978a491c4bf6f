#!/usr/bin/env python3
"""Load benchmark of the Modbus/TCP server: `ferrobus sim --tcp` beside pymodbus's TCP server.

For 10, 100 and 1,000 concurrent clients on 127.0.0.1, each client writes its own register
(0x06, address = client index, a value of its own each round) and reads it back (0x03), in a
loop bounded in rounds and in time. Measured per server and level:

- mismatches: a read-back that is not the value written, a reply with the wrong transaction
  id, unit or function, or a connection lost (goal 0);
- p50 / p99 of one transaction's round trip, as the client sees it;
- server CPU (user + system, from /proc/PID/stat) per transaction;
- server RSS (VmRSS) idle before the run, and after each level with its clients connected.

The client is plain asyncio over raw MBAP frames, so that its own cost stays small and equal
for both servers. It targets only 127.0.0.1. Writes bench/TCP_LOAD.md (results section) and
prints the same table.

Usage: bench/tcp_load.py [--ferrobus PATH] [--rounds N] [--time-limit S] [--quick]
"""

import argparse
import asyncio
import os
import socket
import statistics
import struct
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LEVELS = (10, 100, 1000)
CLK_TCK = os.sysconf("SC_CLK_TCK")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK_TCK


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


class Server:
    def __init__(self, name, argv, ready_stream, ready):
        self.name = name
        port = free_port()
        self.port = port
        argv = [a.replace("{port}", str(port)) for a in argv]
        self.proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        stream = self.proc.stdout if ready_stream == "out" else self.proc.stderr
        deadline = time.monotonic() + 20
        for line in stream:
            if ready(line.strip()):
                break
            if time.monotonic() > deadline:
                raise SystemExit(f"{name} did not get ready")
        else:
            raise SystemExit(f"{name} exited: {self.proc.stderr.read()}")
        # Keep draining both pipes so the server never blocks on a full pipe.
        for s in (self.proc.stdout, self.proc.stderr):
            os.set_blocking(s.fileno(), False)

    def drain(self):
        for s in (self.proc.stdout, self.proc.stderr):
            try:
                s.read()
            except (OSError, TypeError):
                pass

    def stop(self):
        self.proc.terminate()
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


async def client(index, port, rounds, deadline, latencies, stats, connected, go):
    unit = 1
    address = index % 1000
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
    except OSError as e:
        stats["errors"].append(f"client {index}: connect: {e}")
        connected.release()
        return
    connected.release()
    await go.wait()
    t = (index * 977) & 0xFFFF

    async def transact(pdu):
        nonlocal t
        t = (t + 1) & 0xFFFF
        frame = struct.pack(">HHHB", t, 0, len(pdu) + 1, unit) + pdu
        start = time.perf_counter()
        writer.write(frame)
        header = await reader.readexactly(7)
        tid, proto, length, u = struct.unpack(">HHHB", header)
        body = await reader.readexactly(length - 1)
        latencies.append(time.perf_counter() - start)
        if tid != t or proto != 0 or u != unit:
            stats["mismatches"] += 1
        return body

    try:
        for r in range(rounds):
            if time.monotonic() > deadline:
                stats["cut"] += 1
                break
            value = (index * 31 + r * 7919) & 0xFFFF
            reply = await transact(struct.pack(">BHH", 0x06, address, value))
            if reply != struct.pack(">BHH", 0x06, address, value):
                stats["mismatches"] += 1
            reply = await transact(struct.pack(">BHH", 0x03, address, 1))
            if reply != struct.pack(">BBH", 0x03, 2, value):
                stats["mismatches"] += 1
            stats["transactions"] += 2
    except (OSError, asyncio.IncompleteReadError) as e:
        stats["mismatches"] += 1
        stats["errors"].append(f"client {index}: {e!r}")
    finally:
        writer.close()


async def level(server, clients, rounds, time_limit):
    latencies = []
    stats = {"transactions": 0, "mismatches": 0, "cut": 0, "errors": []}
    connected = asyncio.Semaphore(0)
    go = asyncio.Event()
    deadline = time.monotonic() + time_limit
    tasks = [
        asyncio.create_task(client(i, server.port, rounds, deadline, latencies, stats, connected, go))
        for i in range(clients)
    ]
    for _ in range(clients):
        await connected.acquire()
    await asyncio.sleep(0.2)
    rss_connected = rss_kib(server.proc.pid)
    cpu0 = cpu_seconds(server.proc.pid)
    wall0 = time.perf_counter()
    go.set()
    await asyncio.gather(*tasks)
    wall = time.perf_counter() - wall0
    cpu = cpu_seconds(server.proc.pid) - cpu0
    server.drain()
    n = stats["transactions"]
    latencies.sort()

    def q(p):
        return latencies[min(len(latencies) - 1, int(p * len(latencies)))] * 1e6 if latencies else float("nan")

    return {
        "server": server.name,
        "clients": clients,
        "transactions": n,
        "mismatches": stats["mismatches"],
        "cut": stats["cut"],
        "errors": stats["errors"][:3],
        "p50_us": q(0.50),
        "p99_us": q(0.99),
        "cpu_us_per_tx": cpu / n * 1e6 if n else float("nan"),
        "tx_per_s": n / wall if wall else 0.0,
        "rss_connected_kib": rss_connected,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ferrobus", default=str(ROOT / "target/release/ferrobus"))
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--rounds", type=int, default=0, help="rounds per client (default: 10000 round trips per level)")
    ap.add_argument("--time-limit", type=float, default=60.0, help="seconds per level at most")
    ap.add_argument("--quick", action="store_true", help="a tenth of the rounds")
    ap.add_argument("--out", default=str(ROOT / "bench/TCP_LOAD.md"))
    args = ap.parse_args()
    servers = [
        ("ferrobus sim", [args.ferrobus, "sim", "--profile", "generic", "--max-connections", "1100",
                          "--max-per-source", "1100", "--tcp", "127.0.0.1:{port}"], "err", lambda l: l.startswith("sim: listening on")),
        ("pymodbus 3.16", [args.python, str(ROOT / "tests/peers/pymodbus_server.py"), "--tcp", "{port}"],
         "out", lambda l: l == "READY"),
    ]
    results = []
    idle = {}
    for name, argv, stream, ready in servers:
        server = Server(name, argv, stream, ready)
        try:
            time.sleep(0.5)
            idle[name] = rss_kib(server.proc.pid)
            for clients in LEVELS:
                # 10000 round trips (20000 transactions) per level, at least 2 rounds per client.
                rounds = args.rounds or max(2, 10000 // clients)
                if args.quick:
                    rounds = max(1, rounds // 10)
                r = asyncio.run(level(server, clients, rounds, args.time_limit))
                results.append(r)
                print(f"{r['server']:14} {clients:5} clients: {r['transactions']:6} tx, {r['mismatches']} mismatches, "
                      f"p50 {r['p50_us']:.0f} µs, p99 {r['p99_us']:.0f} µs, {r['cpu_us_per_tx']:.1f} µs CPU/tx, "
                      f"{r['tx_per_s']:.0f} tx/s, RSS {r['rss_connected_kib'] / 1024:.1f} MiB"
                      + (f", errors: {r['errors']}" if r["errors"] else ""), flush=True)
        finally:
            server.stop()
    write_report(args.out, results, idle, args)


def write_report(path, results, idle, args):
    version = subprocess.run([args.ferrobus, "--version"], capture_output=True, text=True).stdout.strip()
    git = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                         text=True).stdout.strip()
    lines = [
        "# Modbus/TCP server under load: ferrobus sim beside pymodbus",
        "",
        "Written by `bench/tcp_load.py` (see its docstring for the method). Each client writes its own",
        "holding register and reads it back; 10,000 round trips per level, split between the clients.",
        "One run on a shared 2-core machine: the client (Python asyncio) shares the cores with the",
        "server, so rates and latencies are the pair's, the CPU per transaction is the server's own.",
        "",
        "## Results",
        "",
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {version} (git {git}), "
        f"load average {os.getloadavg()[0]:.2f}, {os.cpu_count()} CPUs.",
        "",
        "| server | clients | transactions | mismatches | p50 µs | p99 µs | server CPU µs/tx | tx/s | RSS connected MiB |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in results:
        lines.append(f"| {r['server']} | {r['clients']} | {r['transactions']} | {r['mismatches']} | {r['p50_us']:.0f} | "
                     f"{r['p99_us']:.0f} | {r['cpu_us_per_tx']:.1f} | {r['tx_per_s']:.0f} | "
                     f"{r['rss_connected_kib'] / 1024:.1f} |")
    lines.append("")
    lines.append("Idle RSS before the first client: " + ", ".join(f"{k} {v / 1024:.1f} MiB" for k, v in idle.items()) + ".")
    cut = [r for r in results if r["cut"]]
    if cut:
        lines.append("")
        lines.append("Levels cut short by the time limit: " + ", ".join(f"{r['server']} {r['clients']}" for r in cut) + ".")
    Path(path).write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
