#!/usr/bin/env python3
"""bench/bridge/figures.py - the figures of bench/bridge.sh from what it recorded.

    figures.py --run run.json

run.json (written by bridge.sh) names the files and the numbers taken during the run: the
steady window (wall-clock ns), the bridge's CPU ticks and memory over it, the subscriber's
messages, each line's tap record and timing, the ticker's point and period. Printed: a
summary table (markdown) on stdout; the same figures as one JSON object in --json FILE.

Latency. The simulator's ticker point (`ferrobus sim --ticker d005:1.1s`) holds the number of
whole periods of the system clock since the Unix epoch, modulo 65536: the value v received at
instant r began at c = k × period, k the largest count <= r / period with k = v (mod 65536).
End-to-end latency = r - c: the wait for the next poll (the value is read once per second; it
changes every 1.1 s, so every change is read, at a phase that sweeps the cycle) plus the read
on the line plus the bridge, the broker and the subscriber's receive. The DDATA metric's own
timestamp (else the payload's: the bridge's instant of the sample, ms) splits it: sampled -
began is the poll's wait and the line, received - sampled the bridge and MQTT.

Decoding: pysparkplug (the venv's), DDATA with the names of the device's DBIRTH.
"""

from __future__ import annotations

import argparse
import base64
import json
import statistics
import sys
from collections import Counter, defaultdict

WRAP = 65536


def pct(values: list[float], q: float) -> float:
    """The q-quantile (0..1) by nearest rank."""
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, max(0, round(q * len(s) + 0.5) - 1))]


def began_ns(value: int, received_ns: int, period_ns: int) -> int:
    """The instant the ticker's value began, the last count <= received that is value mod WRAP."""
    k = received_ns // period_ns
    return (k - (k - value) % WRAP) * period_ns


# ---- messages -------------------------------------------------------------------------------
def sparkplug(run: dict) -> dict:
    import pysparkplug as spb  # the venv's; imported here so --help works anywhere

    births: dict[str, object] = {}
    kinds: Counter = Counter()
    first_birth_ns = last_dbirth_ns = None
    latency, wait, after = [], [], []
    skipped = 0
    last_value: dict[str, int] = {}
    seq_gaps = 0
    last_seq = None
    metrics_in_window = 0
    ddata_in_window = 0
    start, end = run["window_start_ns"], run["window_end_ns"]
    period_ns = round(run["ticker_period_s"] * 1e9)
    point = run["ticker_point"]
    anomalies = 0
    with open(run["messages"]) as f:
        for line in f:
            m = json.loads(line)
            parts = m["topic"].split("/")
            if len(parts) < 4 or parts[0] != "spBv1.0":
                continue
            kind, device = parts[2], (parts[4] if len(parts) > 4 else None)
            kinds[kind] += 1
            raw = base64.b64decode(m["payload"])
            t = m["t_ns"]
            if kind == "NDEATH":
                continue
            if kind in ("NBIRTH", "DBIRTH"):
                payload = (spb.NBirth if kind == "NBIRTH" else spb.DBirth).decode(raw)
                first_birth_ns = first_birth_ns or t
                if kind == "DBIRTH":
                    births[device] = payload
                    last_dbirth_ns = t
            elif kind == "DDATA":
                payload = spb.DData.decode(raw, birth=births.get(device))
            else:
                payload = None
            seq = getattr(payload, "seq", None)
            if seq is not None:
                if last_seq is not None and seq != (last_seq + 1) % 256 and kind != "NBIRTH":
                    seq_gaps += 1
                last_seq = seq
            if kind != "DDATA" or not (start <= t <= end):
                continue
            ddata_in_window += 1
            metrics_in_window += len(payload.metrics)
            for metric in payload.metrics:
                if metric.name != point or metric.value is None:
                    continue
                value = int(metric.value)
                began = began_ns(value, t, period_ns)
                if t - began > 60 * period_ns:
                    anomalies += 1
                    continue
                latency.append((t - began) / 1e6)
                # The sample's instant: the metric's timestamp, else the payload's.
                stamp = metric.timestamp or payload.timestamp
                if stamp:
                    sampled = stamp * 1_000_000
                    wait.append((sampled - began) / 1e6)
                    after.append((t - sampled) / 1e6)
                if device in last_value:
                    skipped += max(0, (value - last_value[device]) % WRAP - 1)
                last_value[device] = value
    window_s = (end - start) / 1e9
    return {
        "messages": dict(kinds),
        "dbirths": len(births),
        "births_span_ms": round((last_dbirth_ns - first_birth_ns) / 1e6, 1) if births else None,
        "ddata_per_s": round(ddata_in_window / window_s, 1),
        "metrics_per_s": round(metrics_in_window / window_s, 1),
        "latency_ms": summary(latency),
        "sampled_minus_began_ms": summary(wait),
        "received_minus_sampled_ms": summary(after),
        "ticks_skipped": skipped,
        "seq_gaps": seq_gaps,
        "latency_anomalies": anomalies,
    }


def polls(run: dict) -> dict:
    """The check without the bridge: `ferrobus poll --jsonl` records, the ticker's age at each."""
    from datetime import datetime

    start, end = run["window_start_ns"], run["window_end_ns"]
    period_ns = round(run["ticker_period_s"] * 1e9)
    ages, records, failed = [], 0, 0
    last: dict[int, int] = {}
    for path in run["poll_records"]:
        with open(path) as f:
            for line in f:
                r = json.loads(line)
                t = round(datetime.fromisoformat(r["time"].replace("Z", "+00:00")).timestamp() * 1e9)
                if not (start <= t <= end):
                    continue
                records += 1
                failed += r["status"] != "ok"
                for p in r["points"]:
                    if p["point"] == run["ticker_point"] and r["status"] == "ok":
                        value = int(p["raw"])
                        if last.get(r["unit"]) != value:
                            ages.append((t - began_ns(value, t, period_ns)) / 1e6)
                        last[r["unit"]] = value
    return {"poll_records_per_s": round(records / ((end - start) / 1e9), 1), "failed_polls": failed,
            "latency_ms": summary(ages)}


def summary(values: list[float]) -> dict:
    if not values:
        return {"n": 0}
    return {"n": len(values), "p50": round(pct(values, 0.5), 1), "p99": round(pct(values, 0.99), 1),
            "max": round(max(values), 1), "mean": round(statistics.fmean(values), 1)}


# ---- the lines ------------------------------------------------------------------------------
def line_figures(line: dict, start: int, end: int) -> dict:
    """Frames the tap heard in the window: wire time used (characters plus a t3.5 after each
    frame), requests per unit and the distinct requests (the planner's reads) per unit."""
    char_s, t35_s = line["char_us"] / 1e6, line["t35_us"] / 1e6
    frames = chars = 0
    requests: Counter = Counter()
    distinct: dict[int, set] = defaultdict(set)
    reply_chars: dict[tuple, int] = {}
    previous, previous_read = None, None
    with open(line["tap"]) as f:
        for text in f:
            r = json.loads(text)
            if not (start <= r["end_ns"] <= end):
                continue
            data = bytes.fromhex(r["bytes"].replace(" ", ""))
            frames += 1
            chars += len(data)
            # A read request is 8 bytes; the reply follows it. An FC01/02 reply of 8 bytes
            # (byte count 3) is told apart by following a request to the same unit and code.
            is_reply = previous is not None and previous[:2] == data[:2]
            if len(data) == 8 and not is_reply:
                read = (data[1], int.from_bytes(data[2:4], "big"), int.from_bytes(data[4:6], "big"))
                requests[data[0]] += 1
                distinct[data[0]].add(read)
                previous, previous_read = data, (data[0],) + read
            else:
                if previous is not None:
                    reply_chars[previous_read] = len(data)
                previous = None
    window_s = (end - start) / 1e9
    busy_s = chars * char_s + frames * t35_s
    units = len(requests)
    per_cycle = sorted({len(v) for v in distinct.values()})
    # The wire time of one cycle as planned: each distinct read and its reply, two t3.5.
    planned_s = 0.0
    for unit, reads in distinct.items():
        for fc, address, quantity in reads:
            reply = reply_chars.get((unit, fc, address, quantity))
            if reply is None:
                reply = 5 + (2 * quantity if fc in (3, 4) else (quantity + 7) // 8)
            planned_s += (8 + reply) * char_s + 2 * t35_s
    return {
        "name": line["name"],
        "units": units,
        "reads_per_device_per_cycle": per_cycle,
        "requests_per_s": round(sum(requests.values()) / window_s, 1),
        "wire_busy_share": round(busy_s / window_s, 3),
        "planned_wire_s_per_cycle": round(planned_s, 3),
    }


def memory_map(path: str) -> dict:
    """The measured process's resident memory by kind of mapping (/proc/PID/smaps at the end):
    the binary and libraries (file-backed), the [heap] (brk), and anonymous mappings: malloc's
    per-thread arenas (64 MiB reserved each, resident as used) and thread stacks."""
    kinds: Counter = Counter()
    anonymous: list[int] = []
    name = None
    with open(path) as f:
        for line in f:
            fields = line.split()
            if fields and "-" in fields[0] and len(fields) >= 5 and not fields[0].endswith(":"):
                name = fields[5] if len(fields) > 5 else ""
            elif fields and fields[0] == "Rss:":
                rss = int(fields[1])
                if name.startswith("/"):
                    kinds["file-backed"] += rss
                elif name == "[heap]":
                    kinds["heap"] += rss
                elif name == "":
                    kinds["anonymous mappings"] += rss
                    if rss:
                        anonymous.append(rss)
                else:
                    kinds[name] += rss
    top = sorted(anonymous, reverse=True)[:8]
    return {"by_kind_kb": dict(kinds), "anonymous_mappings": len(anonymous), "largest_anonymous_kb": top}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", required=True)
    parser.add_argument("--json")
    args = parser.parse_args()
    run = json.load(open(args.run))
    start, end = run["window_start_ns"], run["window_end_ns"]
    window_s = (end - start) / 1e9
    figures = {k: run[k] for k in ("mode", "baud", "devices", "points_per_device", "binary", "load_average")}
    figures["transport"] = run.get("transport", "serial")
    figures["in_flight"] = run.get("in_flight", 1)
    figures["every"] = run.get("every", "1s")
    figures["window_s"] = round(window_s, 1)
    if run.get("polls_in_window"):
        # A poll is one planned read; a device's points are read in `reads_per_device` of them.
        reads = run["reads_per_device"]
        figures["polls_per_s"] = round(run["polls_in_window"] / window_s, 1)
        figures["points_per_s"] = round(run["polls_in_window"] / window_s * run["points_per_device"] / reads)
    figures["cpu_share_of_one_core"] = round(run["cpu_ticks"] / run["clk_tck"] / window_s, 4)
    if "sys_ticks" in run:
        figures["kernel_share_of_one_core"] = round(run["sys_ticks"] / run["clk_tck"] / window_s, 4)
    figures["rss_kb"] = {"start": run["rss_start_kb"], "end": run["rss_end_kb"], "hwm": run["hwm_kb"]}
    figures["memory_kb"] = run.get("memory_kb", {})
    figures["threads"] = run.get("threads")
    if run.get("smaps"):
        figures["memory_map"] = memory_map(run["smaps"])
    figures.update(sparkplug(run) if run["mode"] == "bridge" else polls(run))
    figures["lines"] = [line_figures(line, start, end) for line in run["lines"]]
    figures["overload_messages"] = run.get("overload_messages", [])
    if args.json:
        with open(args.json, "w") as f:
            json.dump(figures, f)
    print_table(figures)
    return 0


def print_table(f: dict) -> None:
    lat = f["latency_ms"]
    rows = [
        ("run", f"{f['mode']}, {f['devices']} devices × {f['points_per_device']} points every {f['every']}, "
                + (f"{f['baud']} 8N1" if f["transport"] == "serial" else f"Modbus/TCP, {f['in_flight']} in flight")
                + f", {f['window_s']} s window, load average {f['load_average']}"),
        ("binary", f["binary"]),
        ("CPU, share of one core", f"{f['cpu_share_of_one_core'] * 100:.2f} %"
         + (f" ({f['kernel_share_of_one_core'] * 100:.2f} % in the kernel)" if "kernel_share_of_one_core" in f else "")),
        ("RSS start → end of window (VmHWM)",
         f"{f['rss_kb']['start']} → {f['rss_kb']['end']} kB ({f['rss_kb']['hwm']} kB)"),
    ]
    if f["memory_kb"]:
        rows.append(("of which (smaps_rollup at the end)",
                     ", ".join(f"{k} {v} kB" for k, v in f["memory_kb"].items())))
    if f.get("memory_map"):
        m = f["memory_map"]
        rows.append(("resident by mapping (first measured process)",
                     ", ".join(f"{k} {v} kB" for k, v in m["by_kind_kb"].items())
                     + f"; {m['anonymous_mappings']} anonymous mappings resident, the largest "
                     + ", ".join(str(v) for v in m["largest_anonymous_kb"]) + f" kB; {f['threads']} threads"))
    if "polls_per_s" in f:
        rows.append(("polls (reads) per second / points read per second", f"{f['polls_per_s']} / {f['points_per_s']}"))
    rows.append(("latency change → message (n)",
                 f"p50 {lat.get('p50')} ms, p99 {lat.get('p99')} ms, max {lat.get('max')} ms ({lat['n']})"))
    if f["mode"] == "bridge":
        w, a = f["sampled_minus_began_ms"], f["received_minus_sampled_ms"]
        rows += [
            ("  of it: change → sample (poll wait + line)",
             f"p50 {w.get('p50')} ms, p99 {w.get('p99')} ms, max {w.get('max')} ms"),
            ("  of it: sample → received (bridge + MQTT)",
             f"p50 {a.get('p50')} ms, p99 {a.get('p99')} ms, max {a.get('max')} ms"),
            ("messages", ", ".join(f"{k} {v}" for k, v in sorted(f["messages"].items()))),
            ("DDATA / metrics per second", f"{f['ddata_per_s']} / {f['metrics_per_s']}"),
            ("DBIRTHs, first birth → last DBIRTH", f"{f['dbirths']}, {f['births_span_ms']} ms"),
            ("ticks not published (skipped) / seq gaps", f"{f['ticks_skipped']} / {f['seq_gaps']}"),
        ]
    else:
        rows.append(("poll records per second / failed", f"{f['poll_records_per_s']} / {f['failed_polls']}"))
    for line in f["lines"]:
        rows.append((f"line {line['name']}",
                     f"{line['units']} units, {line['reads_per_device_per_cycle']} reads per device per cycle, "
                     f"{line['requests_per_s']} requests/s, wire busy {line['wire_busy_share'] * 100:.1f} % "
                     f"(planned {line['planned_wire_s_per_cycle'] * 1000:.0f} ms per 1 s cycle)"))
    for message in f["overload_messages"]:
        # The bridge's "cannot carry this" lists every read's arithmetic: its head and its total.
        head, _, total = message.partition(": u1 ")
        if total and "that is " in total:
            message = f"{head}: … {total[total.index('that is '):]}"
        rows.append(("overload", message))
    print("| figure | value |\n|---|---|")
    for name, value in rows:
        print(f"| {name} | {value} |")


if __name__ == "__main__":
    sys.exit(main())
