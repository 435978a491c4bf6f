#!/usr/bin/env python3
"""decode.py - what pysparkplug 0.6.1 makes of a Sparkplug B payload, as JSON.

    decode.py TYPE [--birth FILE] [FILE|-]

TYPE is the message type of the payload (NBIRTH, NDATA, NCMD, NDEATH, DBIRTH, DDATA, DCMD,
DDEATH); the payload is read from FILE, or stdin when FILE is '-' or absent. A DATA or CMD
payload whose metrics carry only aliases needs the birth they were announced in: --birth
FILE, an NBIRTH or DBIRTH payload, decoded first, resolves their names and datatypes (as a
host application does).

Prints one JSON object on stdout:

    {"type": "DBIRTH", "timestamp": 1700000000000, "seq": 1,
     "metrics": [{"name": "F001", "alias": 1, "datatype": "UINT16", "datatype_number": 6,
                  "value": 5000, "timestamp": ..., "is_historical": false,
                  "is_transient": false, "is_null": false,
                  "properties": {"engUnit": {"type": 12, "value": "Hz"}}}]}

Values: bytes as lowercase hex, DateTime as milliseconds since the epoch, arrays as lists,
floats as JSON numbers (NaN and infinities as the strings "NaN", "inf", "-inf"). pysparkplug's
Metric has no properties, so they are read from the payload's protobuf message as pysparkplug
parses it (its own sparkplug_b_pb2), one entry per key: {"type": N, "value": V}.

Exit status 0 when pysparkplug decoded the payload; 1 with "error: ..." on stderr when it
refused it (the message is pysparkplug's).

pysparkplug behaviour worth knowing:
  * NDeath.decode inverts its timestamp check (timestamp is None when it is present), so
    NDEATH's timestamp printed here is null; use protoc --decode_raw for it.
  * Int8/16/32 are read as two's complement of the type's own width: an Int16 -5 must be
    int_value 65531; a 32-bit sign extension (4294967291) is refused (OverflowError).
  * UInt32 is read from whichever field is set (int_value or long_value).
"""

import argparse
import base64
import datetime
import json
import math
import sys

import pysparkplug
from pysparkplug import _protobuf as protobuf

TYPES = {
    "NBIRTH": pysparkplug.NBirth,
    "NDATA": pysparkplug.NData,
    "NCMD": pysparkplug.NCmd,
    "NDEATH": pysparkplug.NDeath,
    "DBIRTH": pysparkplug.DBirth,
    "DDATA": pysparkplug.DData,
    "DCMD": pysparkplug.DCmd,
    "DDEATH": pysparkplug.DDeath,
}


def plain(value):
    """A decoded value as JSON can hold it."""
    if isinstance(value, bool) or value is None or isinstance(value, (int, str)):
        return value
    if isinstance(value, float):
        if math.isnan(value):
            return "NaN"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return value
    if isinstance(value, (bytes, bytearray)):
        return bytes(value).hex()
    if isinstance(value, datetime.datetime):
        return round(value.timestamp() * 1000)
    if isinstance(value, (tuple, list)):
        return [plain(v) for v in value]
    return repr(value)


def property_value(value):
    """One protobuf PropertyValue: its type and the value of whichever field is set."""
    field = value.WhichOneof("value")
    if field is None:
        shown = None
    elif field == "propertyset_value":
        shown = properties(value.propertyset_value)
    elif field == "propertysets_value":
        shown = [properties(s) for s in value.propertysets_value.propertyset]
    elif field == "extension_value":
        shown = base64.b16encode(value.extension_value.SerializeToString()).decode().lower()
    else:
        shown = plain(getattr(value, field))
    return {"type": value.type, "field": field, "is_null": value.is_null, "value": shown}


def properties(property_set):
    """A protobuf PropertySet as {key: property value}."""
    return {key: property_value(value) for key, value in zip(property_set.keys, property_set.values)}


def metric_json(metric, raw_metric):
    """One decoded metric, with the properties of its protobuf message."""
    return {
        "name": metric.name,
        "alias": metric.alias,
        "datatype": metric.datatype.name,
        "datatype_number": int(metric.datatype),
        "value": plain(metric.value),
        "timestamp": metric.timestamp,
        "is_historical": metric.is_historical,
        "is_transient": metric.is_transient,
        "is_null": metric.is_null,
        "properties": properties(raw_metric.properties) if raw_metric.HasField("properties") else None,
    }


def decode(kind, raw, birth):
    """The payload as JSON, or raises what pysparkplug raised."""
    cls = TYPES[kind]
    payload = cls.decode(raw, birth=birth) if kind != "NDEATH" else cls.decode(raw)
    raw_payload = protobuf.Payload.FromString(raw)
    if kind == "NDEATH":
        metrics = [payload.bd_seq_metric]
    elif kind == "DDEATH":
        metrics = []
    else:
        metrics = list(payload.metrics)
    return {
        "type": kind,
        "timestamp": getattr(payload, "timestamp", None),
        "seq": getattr(payload, "seq", None),
        "metrics": [metric_json(m, r) for m, r in zip(metrics, raw_payload.metrics)],
    }


def main():
    parser = argparse.ArgumentParser(description="Decode a Sparkplug B payload with pysparkplug.")
    parser.add_argument("type", choices=sorted(TYPES))
    parser.add_argument("file", nargs="?", default="-")
    parser.add_argument("--birth", help="the NBIRTH or DBIRTH payload that announced the aliases")
    args = parser.parse_args()
    raw = sys.stdin.buffer.read() if args.file == "-" else open(args.file, "rb").read()
    try:
        birth = None
        if args.birth:
            born = open(args.birth, "rb").read()
            birth = pysparkplug.DBirth.decode(born) if args.type.startswith("D") else pysparkplug.NBirth.decode(born)
        print(json.dumps(decode(args.type, raw, birth)))
    except Exception as error:  # pysparkplug raises ValueError, OverflowError, KeyError, DecodeError, ...
        print(f"error: {type(error).__name__}: {error}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
