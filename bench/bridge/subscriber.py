#!/usr/bin/env python3
"""bench/bridge/subscriber.py - every MQTT message of a topic filter, with the instant it arrived.

    subscriber.py --port 18830 --out messages.jsonl [--host 127.0.0.1] [--topic 'spBv1.0/#']

One JSON line per message: {"t_ns": receive time (the system clock, nanoseconds since the Unix
epoch, taken in the callback), "topic": ..., "payload": base64}. Decoding is left to
figures.py, so the receive path stays short; births and deaths are flushed to the file at once,
the rest in 64 KiB blocks. Once subscribed it writes "subscribed" on stdout;
SIGTERM or SIGINT ends it after flushing the file. paho-mqtt 1.6.1 (the venv's, with pysparkplug).
"""

from __future__ import annotations

import argparse
import base64
import json
import signal
import sys
import time

import paho.mqtt.client as mqtt


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--topic", default="spBv1.0/#")
    parser.add_argument("--out", required=True)
    args = parser.parse_args()

    out = open(args.out, "w", buffering=1 << 16)
    client = mqtt.Client(client_id="bridgebench-subscriber", clean_session=True)

    def on_connect(client, _userdata, _flags, rc):
        if rc != 0:
            print(f"subscriber: connection refused: {mqtt.connack_string(rc)}", file=sys.stderr)
            client.disconnect()
            return
        client.subscribe(args.topic, qos=0)

    def on_subscribe(_client, _userdata, _mid, granted):
        print("subscribed", flush=True)
        print(f"subscriber: {args.topic} granted QoS {granted}", file=sys.stderr)

    def on_message(_client, _userdata, message):
        t_ns = time.time_ns()
        out.write(json.dumps({"t_ns": t_ns, "topic": message.topic,
                              "payload": base64.b64encode(message.payload).decode()}) + "\n")
        # Births and deaths at once: bridge.sh waits for the births by reading the file.
        if "BIRTH" in message.topic or "DEATH" in message.topic:
            out.flush()

    def stop(_signum, _frame):
        client.disconnect()

    client.on_connect = on_connect
    client.on_subscribe = on_subscribe
    client.on_message = on_message
    signal.signal(signal.SIGTERM, stop)
    signal.signal(signal.SIGINT, stop)
    client.connect(args.host, args.port, keepalive=30)
    client.loop_forever()
    out.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
