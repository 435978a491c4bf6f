#!/usr/bin/env python3
"""Publish Sparkplug B messages built with pysparkplug, or plain text, to a broker.

    publish.py --port P session --group G --node N --device D [--data K] [--break WHAT] [--kill]
    publish.py --port P dcmd --group G --node N --device D (--metric NAME | --alias A)
                             --datatype TYPE --value V
    publish.py --port P rebirth --group G --node N
    publish.py --port P edge-node --group G --node N --device D
    publish.py --port P text --topic T --payload TEXT [--qos Q] [--retain]

`session` plays a small edge node that follows the rules: CONNECT with the NDEATH Will
(QoS 1, bdSeq 7), NBIRTH (seq 0, bdSeq 7, `Node Control/Rebirth`), a DBIRTH of D with two
aliased metrics (`speed` Float with engUnit "Hz", `running` Boolean), K DDATA by alias, then
an NDEATH and a clean disconnect, or with --kill an exit without DISCONNECT (the broker then
publishes the Will). --break spoils one rule, so that a checker can be shown to catch it:
`seq` (a DDATA skips a seq), `birth` (no DBIRTH), `bdseq` (the NDEATH has bdSeq 8),
`alias` (a DDATA names alias 99), `nbirth-seq` (the NBIRTH has seq 1).

`dcmd` sends one DCMD metric (by name, or by alias without a name; TYPE is a pysparkplug
DataType name such as FLOAT, DOUBLE, UINT16); `rebirth` an NCMD `Node Control/Rebirth` =
true; `text` one plain MQTT message. `edge-node` runs pysparkplug's own EdgeNode (connect,
one DDATA, disconnect) as it is: in 0.6.1 its NBIRTH has no Rebirth metric unless given one,
its DDATA carry datatypes, and the NDEATH of its clean disconnect carries the bdSeq of the
*next* connection (it prepares the Will twice), which a checker should catch. Exit 0 once everything was handed to the broker (QoS 1
waits for the PUBACK), 1 if the broker cannot be reached, 2 on bad arguments.
"""

import argparse
import os
import sys
import time

import paho.mqtt.client as mqtt
import pysparkplug as spb
from pysparkplug import _protobuf as pb

BD_SEQ = 7


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, required=True)
    sub = parser.add_subparsers(dest="command", required=True)
    session = sub.add_parser("session")
    session.add_argument("--group", required=True)
    session.add_argument("--node", required=True)
    session.add_argument("--device", required=True)
    session.add_argument("--data", type=int, default=5)
    session.add_argument("--break", dest="spoil", choices=["seq", "birth", "bdseq", "alias", "nbirth-seq"])
    session.add_argument("--kill", action="store_true")
    dcmd = sub.add_parser("dcmd")
    dcmd.add_argument("--group", required=True)
    dcmd.add_argument("--node", required=True)
    dcmd.add_argument("--device", required=True)
    dcmd.add_argument("--metric")
    dcmd.add_argument("--alias", type=int)
    dcmd.add_argument("--datatype", required=True)
    dcmd.add_argument("--value", required=True)
    rebirth = sub.add_parser("rebirth")
    rebirth.add_argument("--group", required=True)
    rebirth.add_argument("--node", required=True)
    edge = sub.add_parser("edge-node")
    edge.add_argument("--group", required=True)
    edge.add_argument("--node", required=True)
    edge.add_argument("--device", required=True)
    text = sub.add_parser("text")
    text.add_argument("--topic", required=True)
    text.add_argument("--payload", required=True)
    text.add_argument("--qos", type=int, default=1)
    text.add_argument("--retain", action="store_true")
    args = parser.parse_args()
    if args.command == "dcmd" and (args.metric is None) == (args.alias is None):
        parser.error("dcmd takes one of --metric and --alias")
    return args


def connect(args, will=None):
    client = mqtt.Client(client_id=f"ferrobus-publish-{os.getpid()}", protocol=mqtt.MQTTv311)
    if will is not None:
        client.will_set(*will)
    try:
        client.connect(args.host, args.port, keepalive=30)
    except OSError as error:
        print(f"publish: {args.host}:{args.port}: {error}", file=sys.stderr)
        sys.exit(1)
    client.loop_start()
    return client


def send(client, topic, payload, qos=0, retain=False):
    info = client.publish(topic, payload, qos=qos, retain=retain)
    info.wait_for_publish(timeout=10)


def now():
    return spb.get_current_timestamp()


def with_unit(metric_pb, unit):
    """Adds the engineering unit property (engUnit, a String) to a protobuf metric."""
    metric_pb.properties.keys.append("engUnit")
    value = metric_pb.properties.values.add()
    value.type = spb.DataType.STRING
    value.string_value = unit
    return metric_pb


def session(args):
    node = f"spBv1.0/{args.group}/%s/{args.node}"
    device = f"spBv1.0/{args.group}/%s/{args.node}/{args.device}"
    bd_metric = spb.Metric(timestamp=now(), name="bdSeq", datatype=spb.DataType.INT64, value=BD_SEQ)
    death_bd = BD_SEQ + 1 if args.spoil == "bdseq" else BD_SEQ
    death = spb.NDeath(timestamp=now(), bd_seq_metric=spb.Metric(
        timestamp=now(), name="bdSeq", datatype=spb.DataType.INT64, value=death_bd))
    client = connect(args, will=(node % "NDEATH", death.encode(), 1, False))
    seq = iter(range(1, 10_000))
    nbirth = spb.NBirth(timestamp=now(), seq=1 if args.spoil == "nbirth-seq" else 0, metrics=(
        bd_metric,
        spb.Metric(timestamp=now(), name="Node Control/Rebirth", datatype=spb.DataType.BOOLEAN, value=False),
    ))
    send(client, node % "NBIRTH", nbirth.encode())
    if args.spoil != "birth":
        speed = spb.Metric(timestamp=now(), name="speed", datatype=spb.DataType.FLOAT, value=0.0, alias=1)
        running = spb.Metric(timestamp=now(), name="running", datatype=spb.DataType.BOOLEAN, value=False, alias=2)
        birth = pb.Payload.FromString(spb.DBirth(timestamp=now(), seq=next(seq) % 256,
                                                 metrics=(speed, running)).encode())
        with_unit(birth.metrics[0], "Hz")
        send(client, device % "DBIRTH", birth.SerializeToString())
    for i in range(args.data):
        n = next(seq)
        if args.spoil == "seq" and i == args.data // 2:
            n = next(seq)
        alias = 99 if args.spoil == "alias" and i == args.data // 2 else 1
        data = spb.DData(timestamp=now(), seq=n % 256, metrics=(
            spb.Metric(timestamp=now(), name=None, alias=alias, datatype=spb.DataType.FLOAT, value=float(i)),
        ))
        send(client, device % "DDATA", data.encode())
        time.sleep(0.01)
    if args.kill:
        # Leave without DISCONNECT: the broker publishes the Will.
        os._exit(0)
    send(client, node % "NDEATH", death.encode(), qos=1)
    client.disconnect()
    client.loop_stop()


def dcmd(args):
    datatype = spb.DataType[args.datatype.upper()]
    text = args.value
    if datatype in (spb.DataType.FLOAT, spb.DataType.DOUBLE):
        value = float(text)
    elif datatype == spb.DataType.BOOLEAN:
        value = text.lower() in ("1", "true", "on")
    elif datatype in (spb.DataType.STRING, spb.DataType.TEXT):
        value = text
    else:
        value = int(text)
    metric = spb.Metric(timestamp=now(), name=args.metric, alias=args.alias, datatype=datatype, value=value)
    payload = spb.DCmd(timestamp=now(), metrics=(metric,)).encode(include_dtypes=True)
    client = connect(args)
    send(client, f"spBv1.0/{args.group}/DCMD/{args.node}/{args.device}", payload, qos=0)
    time.sleep(0.1)
    client.disconnect()
    client.loop_stop()


def rebirth(args):
    metric = spb.Metric(timestamp=now(), name="Node Control/Rebirth", datatype=spb.DataType.BOOLEAN, value=True)
    payload = spb.NCmd(timestamp=now(), metrics=(metric,)).encode(include_dtypes=True)
    client = connect(args)
    send(client, f"spBv1.0/{args.group}/NCMD/{args.node}", payload, qos=0)
    time.sleep(0.1)
    client.disconnect()
    client.loop_stop()


def edge_node(args):
    metric = spb.Metric(timestamp=now(), name="speed", datatype=spb.DataType.FLOAT, value=1.0)
    node = spb.EdgeNode(args.group, args.node, metrics=[])
    node.register(spb.Device(args.device, metrics=[metric]))
    try:
        node.connect(args.host, port=args.port, blocking=False)
    except OSError as error:
        print(f"publish: {args.host}:{args.port}: {error}", file=sys.stderr)
        sys.exit(1)
    time.sleep(0.5)
    node.update_device(args.device, [spb.Metric(timestamp=now(), name="speed", datatype=spb.DataType.FLOAT, value=2.0)])
    time.sleep(0.2)
    node.disconnect()


def text(args):
    client = connect(args)
    send(client, args.topic, args.payload.encode(), qos=args.qos, retain=args.retain)
    client.disconnect()
    client.loop_stop()


def main():
    args = parse_args()
    {"session": session, "dcmd": dcmd, "rebirth": rebirth, "edge-node": edge_node, "text": text}[args.command](args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
