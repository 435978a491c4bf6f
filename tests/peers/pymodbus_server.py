#!/usr/bin/env python3
"""pymodbus_server.py - a Modbus server fixture built on pymodbus 3.16 (asyncio).

Serves the shared data map (tests/peers/README.md) for one unit id, over RTU
on a tty (e.g. one end of a socat pty pair) or over TCP on 127.0.0.1.

    pymodbus_server.py --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 8]
                       [--stop-bits 1|2] [--unit U] [--debug]
    pymodbus_server.py --tcp PORT [--unit U] [--debug]

Contract (the same as libmodbus_server):
  * stdout carries exactly one line, "READY", flushed once requests can be
    accepted; logs and notes go to stderr.
  * SIGTERM / SIGINT stop the server, exit status 0. Bad arguments: usage on
    stderr, exit 2. The port or socket cannot be opened: exit 1.
  * Only unit U is answered, on both transports. Other unit ids, broadcast
    (unit 0) included, get no reply and change nothing.

pymodbus quirks handled here (details in README.md):
  * Without help the server answers every unknown unit id with exception 04
    (its SimCore raises KeyError, which the request handler turns into
    DEVICE_FAILURE; ignore_missing_devices does not catch it). A request
    handler subclass drops such requests instead.
  * Parity E/O cannot be set on a Linux pty: the kernel does not keep PARENB
    and glibc's tcsetattr() then reports EINVAL. pymodbus configures the port
    twice on open (its SerialTransport sets timeout=0 right after opening,
    which makes pyserial apply the termios settings again), so on a pty the
    open fails with termios.error(22). Ptys do not apply parity anyway, so
    the server falls back to parity N with a note on stderr.

Function codes served: 01-07, 08 (diagnostics sub-functions as implemented by
pymodbus), 0B, 0C, 0F, 10, 11, 14, 15 (dummy file records), 16, 17,
18 (dummy FIFO [0, 1, 2, 3]) and 2B/0E (vendor "pymodbus", product code
"PM", revision "<major>.<minor>" of the installed pymodbus).
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import logging
import signal
import sys

try:
    import pymodbus
    from pymodbus.pdu.device import ModbusDeviceIdentification
    from pymodbus.server import ModbusSerialServer, ModbusTcpServer
    from pymodbus.server.requesthandler import ServerRequestHandler
    from pymodbus.simulator import DataType, SimData, SimDevice
except ImportError as exc:  # pragma: no cover - environment problem
    sys.stderr.write(
        f"pymodbus_server: cannot import pymodbus ({exc}); run .ci/setup-peers.sh\n"
    )
    sys.exit(1)

PROG = "pymodbus_server"
REGISTERS = 1000
BITS = 2000


def note(text: str) -> None:
    """Write one line to stderr."""
    sys.stderr.write(f"{PROG}: {text}\n")
    sys.stderr.flush()


def data_map(unit: int) -> SimDevice:
    """Build the shared data map as one pymodbus device with four separate blocks.

    The tuple form (coils, discrete inputs, holding, input) keeps the four
    tables apart and addresses bits one by one. Each block ends exactly at
    the map's end (2000 bits = 125 words, so no padding bits are readable);
    pymodbus answers any address past a block with exception 02.
    """
    return SimDevice(
        id=unit,
        simdata=(
            [SimData(0, values=[i % 3 == 0 for i in range(BITS)], datatype=DataType.BITS)],
            [SimData(0, values=[i % 5 == 0 for i in range(BITS)], datatype=DataType.BITS)],
            [
                SimData(
                    0,
                    values=[(i * 7 + 3) & 0xFFFF for i in range(REGISTERS)],
                    datatype=DataType.REGISTERS,
                )
            ],
            [
                SimData(
                    0,
                    values=[(0x1000 + i) & 0xFFFF for i in range(REGISTERS)],
                    datatype=DataType.REGISTERS,
                    readonly=True,
                )
            ],
        ),
    )


def identity() -> ModbusDeviceIdentification:
    """Device identification for FC 2B/0E (and the FC 11 text, which joins it with '-')."""
    major_minor = ".".join(pymodbus.__version__.split(".")[:2])
    return ModbusDeviceIdentification(
        info_name={
            "VendorName": "pymodbus",
            "ProductCode": "PM",
            "MajorMinorRevision": major_minor,
        }
    )


class UnitFilterHandler(ServerRequestHandler):
    """Request handler that answers one unit id only and stays silent otherwise."""

    unit = 1

    async def handle_request(self):
        """Run the request only when it is addressed to our unit."""
        pdu = self.last_pdu
        if pdu is None or pdu.dev_id != self.unit:
            return
        await super().handle_request()

    def server_send(self, pdu, addr):
        """Never answer another unit.

        The framer path that turns an undecodable request into an exception
        response bypasses handle_request(), so filter here as well.
        """
        if pdu is not None and getattr(pdu, "dev_id", self.unit) != self.unit:
            return
        super().server_send(pdu, addr)


def filtered(server_class, unit: int):
    """Subclass a pymodbus server so every connection uses UnitFilterHandler."""

    class Filtered(server_class):  # type: ignore[misc, valid-type]
        def callback_new_connection(self):
            handler = UnitFilterHandler(
                self, self.trace_packet, self.trace_pdu, self.trace_connect
            )
            handler.unit = unit
            return handler

    return Filtered


async def start_server(args, parity: str):
    """Create and start the server; return it, or None with the reason."""
    common = {
        "identity": identity(),
        "broadcast_enable": False,
        "ignore_missing_devices": True,
    }
    if args.rtu:
        server = filtered(ModbusSerialServer, args.unit)(
            data_map(args.unit),
            port=args.rtu,
            baudrate=args.baud,
            parity=parity,
            bytesize=args.data_bits,
            stopbits=args.stop_bits,
            **common,
        )
    else:
        server = filtered(ModbusTcpServer, args.unit)(
            data_map(args.unit), address=("127.0.0.1", args.tcp), **common
        )
    try:
        # background=True returns once listening (raises if it could not).
        await server.serve_forever(background=True)
    except Exception as exc:  # noqa: BLE001 - termios.error is not an OSError
        reason = repr(exc)
    else:
        return server, None
    # Keep no reference to the exception: its traceback holds the
    # half-built SerialTransport, whose open pyserial port keeps an exclusive
    # flock() on the device, so the retry would fail with EAGAIN. Collect it
    # now so the port is closed before the next attempt.
    try:
        await server.shutdown()
    except Exception:  # noqa: BLE001
        pass
    del server
    gc.collect()
    return None, reason


async def run(args) -> int:
    """Serve until SIGTERM/SIGINT."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)

    server, err = await start_server(args, args.parity)
    # Only the pty parity failure (termios.error EINVAL) falls back; a missing
    # or busy port is an error whatever the parity.
    if server is None and args.rtu and args.parity != "N" and "(22," in str(err):
        note(
            f"cannot open {args.rtu} with parity {args.parity} ({err}); "
            "pyserial cannot set parity on a pty - falling back to parity N"
        )
        server, err = await start_server(args, "N")
    if server is None:
        where = args.rtu if args.rtu else f"127.0.0.1:{args.tcp}"
        note(f"cannot serve on {where}: {err}")
        return 1

    sys.stdout.write("READY\n")
    sys.stdout.flush()
    await stop.wait()
    await server.shutdown()
    return 0


def parse_args(argv):
    """Parse the command line; argparse exits 2 with usage on errors."""
    parser = argparse.ArgumentParser(
        prog="pymodbus_server.py",
        description="Serve the ferrobus peer data map with pymodbus "
        "(prints READY on stdout when serving).",
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--rtu", metavar="PATH", help="serial device (e.g. a socat pty link)")
    where.add_argument(
        "--tcp", metavar="PORT", type=port_number, help="TCP port on 127.0.0.1"
    )
    parser.add_argument("--baud", type=int, default=19200)
    parser.add_argument("--parity", choices=["N", "E", "O"], default="N")
    parser.add_argument("--data-bits", type=int, choices=[5, 6, 7, 8], default=8)
    parser.add_argument("--stop-bits", type=int, choices=[1, 2], default=1)
    parser.add_argument("--unit", type=unit_id, default=1, help="unit id 1..247 (default 1)")
    parser.add_argument("--debug", action="store_true", help="pymodbus debug log on stderr")
    args = parser.parse_args(argv)
    if args.baud <= 0:
        parser.error("--baud must be positive")
    return args


def port_number(text: str) -> int:
    """argparse type: a TCP port."""
    value = int(text)
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError("port must be 1..65535")
    return value


def unit_id(text: str) -> int:
    """argparse type: a server unit id."""
    value = int(text)
    if not 1 <= value <= 247:
        raise argparse.ArgumentTypeError("unit must be 1..247")
    return value


def main(argv=None) -> int:
    """Entry point."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.debug:
        pymodbus.pymodbus_apply_logging_config(logging.DEBUG)
    else:
        # Warnings (bad frames, failed opens) still reach stderr.
        logging.basicConfig(stream=sys.stderr, level=logging.WARNING)
    return asyncio.run(run(args))


if __name__ == "__main__":
    sys.exit(main())
