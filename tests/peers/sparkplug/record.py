#!/usr/bin/env python3
"""Record every MQTT message a broker delivers, one JSON line each.

    record.py --host 127.0.0.1 --port P --out FILE [--filter TOPIC]... [--client-id ID]

Subscribes to spBv1.0/# and every --filter (QoS 1), and appends to FILE one line per
message received:

    {"topic": "...", "qos": 0, "retain": false, "payload": "<hex>", "received": 1764637200.123}

`received` is this process's wall clock in seconds. Each line is flushed as it is written,
so a test can read the file while the recorder runs. After the first SUBACK stdout gets one
line, `READY`, and is flushed; every later reconnection prints `SUBSCRIBED` again.

The session is persistent (clean session off, a fixed client id): a broker that keeps its
sessions across a restart (persistence on) queues what arrives while the recorder is not yet
connected again, so nothing published during that window is missed. The recorder
reconnects every 0.2 s while the broker is away.

Exits 0 on SIGTERM or SIGINT, 2 on bad arguments. Nothing but READY/SUBSCRIBED goes to
stdout; notes go to stderr. Needs paho-mqtt 1.x (the one pysparkplug 0.6.1 pins).
"""

import argparse
import json
import os
import signal
import sys
import time

import paho.mqtt.client as mqtt


def parse_args():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--out", required=True, help="the JSON-lines file to append to")
    parser.add_argument("--filter", action="append", default=[], help="another topic filter")
    parser.add_argument("--client-id", default=None, help="default: ferrobus-recorder-<pid>")
    return parser.parse_args()


def main():
    args = parse_args()
    filters = ["spBv1.0/#"] + [f for f in args.filter if f != "spBv1.0/#"]
    out = open(args.out, "a", encoding="utf-8")
    client_id = args.client_id or f"ferrobus-recorder-{os.getpid()}"
    client = mqtt.Client(client_id=client_id, clean_session=False, protocol=mqtt.MQTTv311)
    client.reconnect_delay_set(min_delay=0.2, max_delay=0.2)
    state = {"ready": False}

    def on_connect(c, _userdata, flags, rc):
        if rc != 0:
            print(f"record: CONNACK {rc}", file=sys.stderr, flush=True)
            return
        if state["ready"] and flags.get("session present"):
            # The broker kept the session and its subscriptions: subscribing again would
            # make it send the retained messages a second time.
            print("record: session present, subscriptions kept", file=sys.stderr, flush=True)
            print("SUBSCRIBED", flush=True)
            return
        c.subscribe([(f, 1) for f in filters])

    def on_subscribe(_c, _userdata, _mid, granted):
        print(f"record: subscribed {filters} granted {list(granted)}", file=sys.stderr, flush=True)
        print("SUBSCRIBED" if state["ready"] else "READY", flush=True)
        state["ready"] = True

    def on_message(_c, _userdata, message):
        line = {
            "topic": message.topic,
            "qos": message.qos,
            "retain": bool(message.retain),
            "payload": message.payload.hex(),
            "received": time.time(),
        }
        out.write(json.dumps(line) + "\n")
        out.flush()

    def on_disconnect(_c, _userdata, rc):
        print(f"record: disconnected ({rc}), reconnecting", file=sys.stderr, flush=True)

    client.on_connect = on_connect
    client.on_subscribe = on_subscribe
    client.on_message = on_message
    client.on_disconnect = on_disconnect

    def stop(_signum, _frame):
        client.disconnect()

    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)

    while True:
        try:
            client.connect(args.host, args.port, keepalive=30)
            break
        except OSError as error:
            print(f"record: connecting to {args.host}:{args.port}: {error}", file=sys.stderr, flush=True)
            time.sleep(0.2)
    client.loop_forever(retry_first_connection=True)
    out.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
