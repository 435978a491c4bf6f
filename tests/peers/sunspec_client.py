#!/usr/bin/env python3
"""pysunspec2's own Modbus/TCP client against a SunSpec device: scan, then read every model.

Usage: sunspec_client.py HOST PORT [UNIT]

Prints one JSON document on stdout: the base address pysunspec2 found, the models of the
chain in order (id and length), and every point of every model it read, as
"MODEL_ID.POINT" (top-level points) -> {"value": raw value, "cvalue": value with its scale
factor applied}. Points the device does not implement are null (pysunspec2's reading).
Exit 1 with the error on stderr when the scan fails.
"""

import json
import sys

import sunspec2.modbus.client as client


def main():
    host, port = sys.argv[1], int(sys.argv[2])
    unit = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    device = client.SunSpecModbusClientDeviceTCP(slave_id=unit, ipaddr=host, ipport=port, timeout=2)
    try:
        device.scan()
        chain = []
        points = {}
        for key, models in device.models.items():
            if not isinstance(key, int):
                continue
            for model in models:
                model.read()
                chain.append({"id": model.model_id, "length": model.model_len})
                for name, point in model.points.items():
                    value = point.value
                    cvalue = point.cvalue
                    if isinstance(value, bytes):
                        value = value.decode("ascii", "replace")
                    points[f"{model.model_id}.{name}"] = {"value": value, "cvalue": cvalue}
        print(json.dumps({"base": device.base_addr, "models": chain, "points": points}))
    except Exception as e:  # noqa: BLE001 - the error is the test's evidence
        print(f"sunspec_client: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    finally:
        device.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
