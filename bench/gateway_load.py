#!/usr/bin/env python3
"""Closed-loop Modbus/TCP clients for bench/gateway.sh: each client sends its next request
when the last reply has arrived.

Each client first writes its own block of 10 holding registers (FC16, values derived from
its index) on its unit, then reads the block back (FC03 x 10) in a loop. The window in which
transactions are counted opens once every client has connected and written its block (after
`--warmup` more seconds) and lasts `--seconds`; a reply counts if it arrived inside it. A reply is a mismatch when its transaction id, unit or function is not the request's, or
a read-back is not the values written; an exception reply is counted by code; a connection
lost is counted as lost. Clients of `--dead-unit` read a unit nobody answers and are
counted apart. Each `--cpu NAME=PID` adds the CPU time the process PID spent (all its
threads, from /proc/PID/task/*/schedstat) while the window was open, and that per counted
transaction, under "cpu" (with "clients": this program's own, when any `--cpu` is given).
Prints one JSON object.

Usage: gateway_load.py --addr HOST:PORT --clients N --seconds S [--units 1,2,...]
                       [--dead-unit U --dead-clients K] [--cpu NAME=PID ...]
"""

import argparse
import asyncio
import json
import os
import statistics
import struct
import time


def frame(tid: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu


async def read_reply(reader):
    head = await reader.readexactly(7)
    tid, _proto, length, unit = struct.unpack(">HHHB", head)
    pdu = await reader.readexactly(length - 1)
    return tid, unit, pdu


class Client:
    def __init__(self, index, unit, dead):
        self.index = index
        self.unit = unit
        self.dead = dead
        self.done = 0
        self.latencies = []
        self.mismatches = 0
        self.exceptions = {}
        self.lost = False
        self.start = (index * 10) % 60000
        self.values = [(index * 31 + i) & 0xFFFF for i in range(10)]

    async def ask(self, reader, writer, tid, pdu):
        writer.write(frame(tid, self.unit, pdu))
        await writer.drain()
        got_tid, got_unit, reply = await read_reply(reader)
        if got_tid != tid or got_unit != self.unit:
            self.mismatches += 1
        return reply

    async def run(self, host, port, ready, window, timeout):
        try:
            reader, writer = await asyncio.wait_for(asyncio.open_connection(host, port), timeout)
        except (OSError, asyncio.TimeoutError):
            self.lost = True
            await ready.leave()
            return
        tid = 0
        try:
            if not self.dead:
                pdu = struct.pack(">BHHB", 0x10, self.start, 10, 20) + struct.pack(">10H", *self.values)
                reply = await asyncio.wait_for(self.ask(reader, writer, tid, pdu), timeout)
                if reply[0] != 0x10:
                    self.exceptions[reply[1] if len(reply) > 1 else -1] = 1
            request = struct.pack(">BHH", 0x03, self.start, 10)
            expected = bytes([0x03, 20]) + struct.pack(">10H", *self.values)
            # Every client is connected and has written its block before the window opens.
            await ready.arrive()
            begin, until = window
            while time.monotonic() < until:
                tid = (tid + 1) & 0xFFFF
                sent = time.monotonic()
                reply = await asyncio.wait_for(self.ask(reader, writer, tid, request), timeout)
                took = time.monotonic() - sent
                arrived = sent + took
                counted = begin[0] <= arrived <= until
                if reply[0] & 0x80:
                    if not counted:
                        continue
                    code = reply[1] if len(reply) > 1 else -1
                    self.exceptions[code] = self.exceptions.get(code, 0) + 1
                    continue
                if reply != expected:
                    self.mismatches += 1
                    continue
                if counted:
                    self.done += 1
                    self.latencies.append(took)
        except (OSError, asyncio.IncompleteReadError, asyncio.TimeoutError):
            self.lost = True
            await ready.leave()
        finally:
            writer.close()


class Barrier:
    """Opens the measuring window once every client has arrived (or given up)."""

    def __init__(self, n, seconds, warmup):
        self.left = n
        self.event = asyncio.Event()
        self.seconds = seconds
        self.warmup = warmup
        self.begin = [float("inf")]
        self.until = float("inf")

    async def arrive(self):
        await self.leave()
        await self.event.wait()

    async def leave(self):
        if self.left > 0:
            self.left -= 1
            if self.left == 0:
                now = time.monotonic()
                self.begin[0] = now + self.warmup
                self.until = now + self.warmup + self.seconds
                self.event.set()


def cpu_ns(pid):
    """The CPU time of every thread of process pid so far, in nanoseconds (None if it is gone)."""
    total = 0
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return None
    for task in tasks:
        try:
            with open(f"/proc/{pid}/task/{task}/schedstat") as f:
                total += int(f.read().split()[0])
        except (OSError, ValueError, IndexError):
            pass  # a thread that ended between the listing and the read
    return total


async def sample_cpu(ready, pids):
    """CPU seconds of each named process over the window: {name: (seconds, sampled interval)}."""
    await ready.event.wait()
    await asyncio.sleep(max(0.0, ready.begin[0] - time.monotonic()))
    start = {name: cpu_ns(pid) for name, pid in pids.items()}
    t0 = time.monotonic()
    await asyncio.sleep(max(0.0, ready.until - t0))
    t1 = time.monotonic()
    out = {}
    for name, pid in pids.items():
        end = cpu_ns(pid)
        if start[name] is not None and end is not None:
            out[name] = ((end - start[name]) / 1e9, t1 - t0)
    return out


def named_pid(text):
    name, sep, pid = text.partition("=")
    if not sep or not name or not pid.isdigit():
        raise argparse.ArgumentTypeError(f"want NAME=PID, not {text!r}")
    return name, int(pid)


async def main():
    p = argparse.ArgumentParser()
    p.add_argument("--addr", required=True)
    p.add_argument("--clients", type=int, required=True)
    p.add_argument("--seconds", type=float, required=True)
    p.add_argument("--units", default="1")
    p.add_argument("--dead-unit", type=int)
    p.add_argument("--dead-clients", type=int, default=0)
    p.add_argument("--timeout", type=float, default=120.0)
    p.add_argument("--warmup", type=float, default=0.0, help="seconds run before the window opens")
    p.add_argument("--cpu", type=named_pid, action="append", default=[], metavar="NAME=PID",
                   help="report the CPU time of process PID over the window (repeatable)")
    a = p.parse_args()
    host, port = a.addr.rsplit(":", 1)
    units = [int(u) for u in a.units.split(",")]
    clients = [Client(i, units[i % len(units)], False) for i in range(a.clients)]
    clients += [Client(a.clients + i, a.dead_unit, True) for i in range(a.dead_clients)]
    ready = Barrier(len(clients), a.seconds, a.warmup)

    class Window:
        def __iter__(self):
            return iter((ready.begin, ready.until))

    watched = dict(a.cpu, clients=os.getpid()) if a.cpu else {}
    sampler = asyncio.create_task(sample_cpu(ready, watched)) if watched else None
    await asyncio.gather(*(c.run(host, int(port), ready, Window(), a.timeout) for c in clients))
    cpu = {}
    if sampler is not None:
        if ready.event.is_set():
            sampled = await sampler
        else:
            sampler.cancel()
            sampled = {}
        for name, (seconds, interval) in sampled.items():
            # Scaled from the sampled interval to the window (they differ by the loop's lateness).
            in_window = seconds * a.seconds / interval if interval > 0 else seconds
            cpu[name] = {
                "seconds": round(in_window, 4),
                "share": round(seconds / interval, 4) if interval > 0 else None,
            }
    elapsed = a.seconds
    live = [c for c in clients if not c.dead]
    counts = [c.done for c in live]
    lat = sorted(x for c in live for x in c.latencies)
    exceptions = {}
    for c in live:
        for code, n in c.exceptions.items():
            exceptions[str(code)] = exceptions.get(str(code), 0) + n
    dead_exceptions = {}
    for c in clients:
        if c.dead:
            for code, n in c.exceptions.items():
                dead_exceptions[str(code)] = dead_exceptions.get(str(code), 0) + n
    done = sum(counts)
    for entry in cpu.values():
        entry["us_per_transaction"] = round(entry["seconds"] * 1e6 / done, 2) if done else None
    q = lambda f: round(lat[min(len(lat) - 1, int(f * len(lat)))] * 1000, 2) if lat else None
    print(json.dumps({
        "clients": a.clients,
        "seconds": round(elapsed, 2),
        "warmup": a.warmup,
        "transactions": sum(counts),
        "tps": round(sum(counts) / elapsed, 2),
        "fairness_max_min": round(max(counts) / min(counts), 3) if counts and min(counts) > 0 else None,
        "min_per_client": min(counts) if counts else 0,
        "max_per_client": max(counts) if counts else 0,
        "p50_ms": q(0.5),
        "p99_ms": q(0.99),
        "mismatches": sum(c.mismatches for c in clients),
        "lost": sum(1 for c in clients if c.lost),
        "exceptions": exceptions,
        "dead_unit_exceptions": dead_exceptions,
        **({"cpu": cpu} if a.cpu else {}),
    }))


if __name__ == "__main__":
    asyncio.run(main())
