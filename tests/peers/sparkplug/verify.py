#!/usr/bin/env python3
"""Check a recording of Sparkplug B traffic against the rules of Sparkplug 3.0.

    verify.py RECORDING [--no-historical] [--series DEVICE/METRIC]... [--expect-unit DEVICE/METRIC=UNIT]...

RECORDING is the JSON-lines file of record.py. Every message on spBv1.0/... is decoded with
pysparkplug (which carries the published sparkplug_b.proto); the engineering units, which
pysparkplug's Metric does not expose, are read from the same generated protobuf types. The
rules, per edge node (a session runs from an NBIRTH to its NDEATH or the next NBIRTH):

- every payload decodes; BIRTH metrics have a name and a datatype (pysparkplug refuses them
  otherwise); DATA metrics carry none (a warning: the spec says SHOULD NOT);
- NBIRTH before any other message of the node; its seq is 0; it has the metrics `bdSeq`
  (an integer 0..255) and `Node Control/Rebirth` (Boolean); a rebirth keeps the bdSeq;
- seq is the previous message's + 1 mod 256 within the session (NBIRTH, NDATA, DBIRTH,
  DDATA, DDEATH; NDEATH has none);
- DBIRTH of a device before its DDATA, and again after its DDEATH; aliases unique per node;
  every DDATA metric resolves (alias or name) to a metric of the device's DBIRTH;
- NDEATH has only `bdSeq`, equal to the open session's NBIRTH bdSeq; nothing of the node
  follows an NDEATH until the next NBIRTH;
- with --no-historical, no metric is marked historical; --expect-unit checks a DBIRTH's
  engineering unit (property `engUnit`).

Prints one JSON summary on stdout (messages by type, sessions with their bdSeq, devices with
their metrics' alias, datatype and unit, the value fields used per datatype, the --series
values with timestamps and historical flags, errors and warnings). Exit 0 when there are no
errors, 1 when there are, 2 on bad arguments or an unreadable file.
"""

import argparse
import json
import sys

import pysparkplug as spb
from pysparkplug import _protobuf as pb

EDGE_TYPES = {"NBIRTH", "NDATA", "NDEATH", "DBIRTH", "DDATA", "DDEATH"}
UNIT_KEYS = ("engUnit", "engUnits", "EngUnit", "units")


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recording")
    parser.add_argument("--no-historical", action="store_true", help="any historical metric is an error")
    parser.add_argument("--series", action="append", default=[], metavar="DEVICE/METRIC")
    parser.add_argument("--expect-unit", action="append", default=[], metavar="DEVICE/METRIC=UNIT")
    return parser.parse_args()


def jsonable(value):
    """A metric value as JSON can carry it."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    if isinstance(value, bytes):
        return value.hex()
    return str(value)


def property_string(metric, keys):
    """The string property of a protobuf metric under one of `keys`, or None."""
    if not metric.HasField("properties"):
        return None
    props = metric.properties
    for key, value in zip(props.keys, props.values):
        if key in keys and value.HasField("string_value"):
            return value.string_value
    return None


class Node:
    """What is known of one edge node while the recording is read."""

    def __init__(self, name):
        self.name = name
        self.session = None  # index into Checker.sessions of the open session
        self.bdseq = None
        self.seq = None
        self.dead = True  # no NBIRTH yet, or after NDEATH
        self.births = {}  # device -> pysparkplug DBirth of this session
        self.device_dead = {}  # device -> bool
        self.aliases = {}  # alias -> (device or None, metric name)


class Checker:
    def __init__(self, args):
        self.args = args
        self.errors = []
        self.warnings = []
        self.by_type = {}
        self.sessions = []
        self.nodes = {}
        self.devices = {}
        self.value_fields = {}
        self.historical = 0
        self.commands = 0
        self.other = 0
        self.series = {key: [] for key in args.series}
        self.index = 0

    def error(self, text):
        self.errors.append(f"message {self.index}: {text}")

    def warning(self, text):
        self.warnings.append(f"message {self.index}: {text}")

    # ---- one recorded line -------------------------------------------------------------

    def line(self, record):
        topic_text = record.get("topic", "")
        raw = bytes.fromhex(record.get("payload", ""))
        parts = topic_text.split("/")
        if len(parts) < 2 or parts[0] != "spBv1.0":
            self.other += 1
            return
        if parts[1] == "STATE":
            self.count("STATE")
            return
        if len(parts) not in (4, 5):
            self.error(f"topic {topic_text!r} is not spBv1.0/GROUP/TYPE/NODE[/DEVICE]")
            return
        kind = parts[2]
        self.count(kind)
        if kind in ("NCMD", "DCMD"):
            self.commands += 1
            return
        if kind not in EDGE_TYPES:
            self.error(f"topic {topic_text!r}: unknown message type {kind!r}")
            return
        device = parts[4] if len(parts) == 5 else None
        if (device is None) != kind.startswith("N"):
            self.error(f"topic {topic_text!r}: {kind} {'needs' if device is None else 'takes no'} device id")
            return
        node = self.nodes.setdefault(f"{parts[1]}/{parts[3]}", Node(f"{parts[1]}/{parts[3]}"))
        try:
            proto = pb.Payload.FromString(raw)
        except Exception as error:  # noqa: BLE001 - any decode failure is a finding
            self.error(f"{topic_text}: the payload does not decode as a Sparkplug B Payload: {error}")
            return
        handler = getattr(self, kind.lower())
        handler(node, device, raw, proto, record)

    def count(self, kind):
        self.by_type[kind] = self.by_type.get(kind, 0) + 1

    def decode(self, cls, raw, what, birth=None):
        try:
            return cls.decode(raw, birth=birth)
        except Exception as error:  # noqa: BLE001
            self.error(f"{what}: pysparkplug cannot decode it: {type(error).__name__}: {error}")
            return None

    def note_fields(self, proto):
        for metric in proto.metrics:
            field = metric.WhichOneof("value")
            if field is not None and metric.datatype:
                name = spb.DataType(metric.datatype).name
                fields = self.value_fields.setdefault(name, [])
                if field not in fields:
                    fields.append(field)

    def next_seq(self, node, payload, what):
        """Checks `payload.seq` against the session's counter and advances it."""
        seq = getattr(payload, "seq", None)
        if seq is None:
            self.error(f"{what}: no seq")
            return
        if node.seq is not None and seq != (node.seq + 1) % 256:
            self.error(f"{what}: seq {seq}, expected {(node.seq + 1) % 256}")
        node.seq = seq
        if node.session is not None:
            self.sessions[node.session]["messages"] += 1

    def alive(self, node, what):
        if node.dead:
            self.error(f"{what} of {node.name} without an NBIRTH before it (none yet, or after an NDEATH)")
            return False
        return True

    # ---- the message types -------------------------------------------------------------

    def nbirth(self, node, _device, raw, proto, record):
        what = f"NBIRTH {node.name}"
        birth = self.decode(spb.NBirth, raw, what)
        if birth is None:
            return
        self.note_fields(proto)
        if birth.seq != 0:
            self.error(f"{what}: seq {birth.seq}, the spec wants 0")
        metrics = {m.name: m for m in birth.metrics}
        bd = metrics.get("bdSeq")
        if bd is None or not isinstance(bd.value, int) or not 0 <= bd.value <= 255:
            self.error(f"{what}: no integer bdSeq metric in 0..255 (got {bd})")
            bdseq = None
        else:
            bdseq = bd.value
        rebirth = metrics.get("Node Control/Rebirth")
        if rebirth is None or rebirth.datatype != spb.DataType.BOOLEAN:
            self.error(f"{what}: no Boolean metric 'Node Control/Rebirth' (got {rebirth})")
        self.check_historical(birth.metrics, what)
        if not node.dead and node.bdseq == bdseq:
            # A rebirth: the same session goes on with a new seq 0.
            self.sessions[node.session]["rebirths"] += 1
        else:
            if not node.dead and node.session is not None:
                self.sessions[node.session]["ended"] = "next NBIRTH"
            node.session = len(self.sessions)
            self.sessions.append({
                "node": node.name, "bdseq": bdseq, "messages": 0, "rebirths": 0, "ended": "open",
                "ndeath_bdseq": None, "ndeath_qos": None, "ndeath_retain": None,
                "nbirth_qos": record.get("qos"), "nbirth_retain": record.get("retain"),
                "metrics": sorted(metrics),
            })
        node.bdseq = bdseq
        node.dead = False
        node.seq = None
        node.births = {}
        node.device_dead = {}
        node.aliases = {}
        self.register_aliases(node, None, birth.metrics, what)
        self.next_seq(node, birth, what)

    def register_aliases(self, node, device, metrics, what):
        for m in metrics:
            if m.alias is None:
                continue
            owner = node.aliases.get(m.alias)
            if owner is not None and owner != (device, m.name):
                self.error(f"{what}: alias {m.alias} of {m.name!r} is already {owner[1]!r} of {owner[0]}")
            node.aliases[m.alias] = (device, m.name)

    def ndata(self, node, _device, raw, _proto, _record):
        what = f"NDATA {node.name}"
        if not self.alive(node, what):
            return
        data = self.decode(spb.NData, raw, what)
        if data is not None:
            self.next_seq(node, data, what)

    def ndeath(self, node, _device, raw, proto, record):
        what = f"NDEATH {node.name}"
        death = self.decode(spb.NDeath, raw, what)
        if death is None:
            return
        if proto.HasField("seq"):
            self.error(f"{what}: carries seq {proto.seq}; an NDEATH has none")
        if len(proto.metrics) != 1 or proto.metrics[0].name != "bdSeq":
            self.error(f"{what}: metrics {[m.name for m in proto.metrics]}, expected only bdSeq")
        bdseq = death.bd_seq_metric.value
        if node.dead:
            earlier = [s for s in self.sessions if s["node"] == node.name and s["bdseq"] == bdseq]
            if earlier:
                self.warning(f"{what}: bdSeq {bdseq} of a session already ended (stale, ignored)")
            else:
                self.error(f"{what}: bdSeq {bdseq} with no session open and none before with it")
            return
        session = self.sessions[node.session]
        if bdseq != node.bdseq:
            self.error(f"{what}: bdSeq {bdseq} differs from the session's NBIRTH bdSeq {node.bdseq}")
        session.update(ended="NDEATH", ndeath_bdseq=bdseq, ndeath_qos=record.get("qos"),
                       ndeath_retain=record.get("retain"))
        node.dead = True

    def dbirth(self, node, device, raw, proto, _record):
        what = f"DBIRTH {node.name}/{device}"
        if not self.alive(node, what):
            return
        birth = self.decode(spb.DBirth, raw, what)
        if birth is None:
            return
        self.note_fields(proto)
        self.check_historical(birth.metrics, what)
        self.register_aliases(node, device, birth.metrics, what)
        node.births[device] = birth
        node.device_dead[device] = False
        info = self.devices.setdefault(device, {"node": node.name, "dbirths": 0, "ddeaths": 0, "ddata": 0,
                                                "metrics": {}})
        info["dbirths"] += 1
        for m, pm in zip(birth.metrics, proto.metrics):
            info["metrics"][m.name] = {
                "alias": m.alias,
                "datatype": m.datatype.name,
                "unit": property_string(pm, UNIT_KEYS),
                "value": jsonable(m.value),
            }
        self.next_seq(node, birth, what)

    def ddata(self, node, device, raw, proto, record):
        what = f"DDATA {node.name}/{device}"
        if not self.alive(node, what):
            return
        birth = node.births.get(device)
        if birth is None or node.device_dead.get(device):
            self.error(f"{what}: no DBIRTH of the device before it in this session"
                       + (" (it had a DDEATH)" if node.device_dead.get(device) else ""))
            self.next_seq(node, proto, what)
            return
        for pm in proto.metrics:
            if pm.HasField("datatype") and pm.datatype:
                self.warning(f"{what}: metric {pm.name or pm.alias} carries a datatype (SHOULD NOT in DATA)")
                break
        known = {m.alias for m in birth.metrics if m.alias is not None}
        names = {m.name for m in birth.metrics}
        for pm in proto.metrics:
            if pm.name and pm.name not in names:
                self.error(f"{what}: metric name {pm.name!r} is not in the device's DBIRTH")
                self.next_seq(node, proto, what)
                return
            if not pm.name and pm.alias not in known:
                self.error(f"{what}: alias {pm.alias} is not in the device's DBIRTH")
                self.next_seq(node, proto, what)
                return
        data = self.decode(spb.DData, raw, what, birth=birth)
        if data is None:
            self.next_seq(node, proto, what)
            return
        self.note_fields(proto)
        self.check_historical(data.metrics, what)
        self.devices[device]["ddata"] += 1
        for m in data.metrics:
            key = f"{device}/{m.name}"
            if key in self.series:
                self.series[key].append({
                    "timestamp": m.timestamp if m.timestamp is not None else data.timestamp,
                    "value": jsonable(m.value), "null": m.is_null, "historical": m.is_historical,
                    "seq": data.seq, "session": node.session, "received": record.get("received"),
                })
        self.next_seq(node, data, what)

    def ddeath(self, node, device, raw, _proto, _record):
        what = f"DDEATH {node.name}/{device}"
        if not self.alive(node, what):
            return
        death = self.decode(spb.DDeath, raw, what)
        if death is None:
            return
        if device not in node.births:
            self.error(f"{what}: the device was never born in this session")
        node.device_dead[device] = True
        info = self.devices.setdefault(device, {"node": node.name, "dbirths": 0, "ddeaths": 0, "ddata": 0,
                                                "metrics": {}})
        info["ddeaths"] += 1
        self.next_seq(node, death, what)

    def check_historical(self, metrics, what):
        marked = [m.name or str(m.alias) for m in metrics if m.is_historical]
        self.historical += len(marked)
        if marked and self.args.no_historical:
            self.error(f"{what}: metrics marked historical: {marked}")

    # ---- the end -----------------------------------------------------------------------

    def finish(self):
        for expectation in self.args.expect_unit:
            key, _, unit = expectation.partition("=")
            device, _, metric = key.partition("/")
            got = self.devices.get(device, {}).get("metrics", {}).get(metric, {}).get("unit")
            if got != unit:
                self.errors.append(f"engineering unit of {device}/{metric}: expected {unit!r}, DBIRTH has {got!r}")
        return {
            "messages": self.index,
            "by_type": self.by_type,
            "sessions": self.sessions,
            "devices": self.devices,
            "value_fields": self.value_fields,
            "historical": self.historical,
            "commands": self.commands,
            "other_topics": self.other,
            "series": self.series,
            "errors": self.errors,
            "warnings": self.warnings,
        }


def main():
    args = parse_args()
    checker = Checker(args)
    try:
        with open(args.recording, encoding="utf-8") as recording:
            for text in recording:
                if not text.strip():
                    continue
                try:
                    record = json.loads(text)
                except json.JSONDecodeError as error:
                    checker.error(f"not a JSON line: {error}: {text[:80]!r}")
                    continue
                checker.line(record)
                checker.index += 1
    except OSError as error:
        print(f"verify: {args.recording}: {error}", file=sys.stderr)
        return 2
    summary = checker.finish()
    print(json.dumps(summary, indent=1))
    return 1 if summary["errors"] else 0


if __name__ == "__main__":
    sys.exit(main())
