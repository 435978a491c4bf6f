#!/usr/bin/env python3
"""pymodbus_client.py - a Modbus client fixture built on pymodbus 3.16 (asyncio).

    pymodbus_client.py CONN [--unit U] [--timeout-ms N] [--debug] script
    pymodbus_client.py CONN [--unit U] [--timeout-ms N] [--debug] bench --count N
                       [--address A] [--quantity Q]

    CONN is --rtu PATH [--baud B] [--parity N|E|O] [--data-bits 8] [--stop-bits 1|2]
         or --tcp HOST:PORT
         or --tls HOST:PORT --ca FILE [--cert FILE --key FILE]  (Modbus/TCP Security)

script reads one command per line on stdin and prints exactly one result line
per command on stdout ("ok ...", "exception N", "timeout", "error TEXT"); blank
lines and lines starting with '#' are skipped. bench performs N FC03 reads
back to back and prints one JSON object. The line format and the command list
are the contract in tests/peers/README.md, shared with libmodbus_client and
tokio-modbus-peer.

The async client is used throughout: pymodbus's sync client polls the port,
so its rate follows the baud setting even on a pty.

pymodbus behaviour worth knowing (see README.md):
  * retries=0, so one command is one request; the "close after retries+3
    silent requests" rule is pushed out of reach with set_max_no_responses(),
    so a timeout test does not tear the TCP connection down.
  * pymodbus decodes an FC 11 reply as <identifier...><status>, taking the
    LAST byte as the run indicator; the spec puts it second. A raw response
    class is registered so "report_slave_id" prints the bytes as received.
  * parity E/O on a pty fails (termios.error EINVAL); falls back to N.

Exit status: 0 after stdin is exhausted or the bench finished; 1 when the
port/connection cannot be opened; 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import asyncio
import gc
import json
import logging
import re
import resource
import ssl
import struct
import sys
import time

try:
    import pymodbus
    from pymodbus.client import AsyncModbusSerialClient, AsyncModbusTcpClient, AsyncModbusTlsClient
    from pymodbus.exceptions import ModbusException, ModbusIOException
    from pymodbus.pdu import ExceptionResponse, ModbusPDU
    from pymodbus.pdu.diag_message import DiagnosticBase
    from pymodbus.pdu.file_message import FileRecord
    from pymodbus.pdu.other_message import ReportDeviceIdRequest
except ImportError as exc:  # pragma: no cover - environment problem
    sys.stderr.write(
        f"pymodbus_client: cannot import pymodbus ({exc}); run .ci/setup-peers.sh\n"
    )
    sys.exit(1)

PROG = "pymodbus_client"


def note(text: str) -> None:
    """Write one line to stderr."""
    sys.stderr.write(f"{PROG}: {text}\n")
    sys.stderr.flush()


class RawReportServerIdResponse(ModbusPDU):
    """FC 11 response that keeps the payload bytes exactly as received."""

    function_code = 0x11
    rtu_byte_count_pos = 2  # RTU size = byte count + 5

    def __init__(self, dev_id: int = 1, transaction_id: int = 0) -> None:
        """Create an empty response (the decoder fills it)."""
        super().__init__(dev_id=dev_id, transaction_id=transaction_id)
        self.raw = b""

    def decode(self, data: bytes) -> None:
        """Keep the bytes after the byte count."""
        count = int(data[0])
        if count > len(data) - 1:
            raise ValueError(f"FC 11 byte count {count} > {len(data) - 1} bytes")
        self.raw = bytes(data[1 : 1 + count])


class Usage(Exception):
    """A script line with bad arguments."""


def num(text: str, lo: int = 0, hi: int = 0xFFFF) -> int:
    """Parse a decimal or 0x-hex number in [lo, hi] (no octal, no sign, no '_')."""
    if re.fullmatch(r"[0-9]+", text):
        value = int(text, 10)
    elif re.fullmatch(r"0[xX][0-9a-fA-F]+", text):
        value = int(text[2:], 16)
    else:
        raise Usage(f"bad number '{text}'")
    if not lo <= value <= hi:
        raise Usage(f"{value} out of range {lo}..{hi}")
    return value


def words_from_bytes(data: bytes) -> list[int]:
    """Big-endian 16-bit words; an odd trailing byte is an error."""
    if len(data) % 2:
        raise ValueError(f"odd byte count {len(data)}")
    return [int.from_bytes(data[i : i + 2], "big") for i in range(0, len(data), 2)]


class Runner:
    """Executes script commands against one pymodbus client."""

    SYNTAX = {
        "read_holding": "read_holding ADDR COUNT",
        "read_input": "read_input ADDR COUNT",
        "read_coils": "read_coils ADDR COUNT",
        "read_discrete": "read_discrete ADDR COUNT",
        "write_coil": "write_coil ADDR 0|1",
        "write_register": "write_register ADDR VALUE",
        "write_coils": "write_coils ADDR 0|1 [0|1 ...]",
        "write_registers": "write_registers ADDR VALUE [VALUE ...]",
        "mask_write": "mask_write ADDR AND OR",
        "write_read": "write_read READ_ADDR READ_COUNT WRITE_ADDR VALUE [VALUE ...]",
        "report_slave_id": "report_slave_id",
        "read_exception_status": "read_exception_status",
        "diag": "diag SUBFUNCTION VALUE",
        "read_device_id": "read_device_id READ_CODE OBJECT_ID",
        "read_fifo": "read_fifo ADDR",
        "read_file": "read_file FILE RECORD LENGTH",
        "write_file": "write_file FILE RECORD VALUE [VALUE ...]",
        "unit": "unit U",
        "sleep": "sleep MS",
    }

    def __init__(self, client, unit: int) -> None:
        """Remember the client and the current unit id."""
        self.client = client
        self.unit = unit

    async def call(self, coro):
        """Await a request; return the response PDU or a result line (str)."""
        try:
            rsp = await coro
        except ModbusIOException as exc:
            # retries=0: "No response received after 0 retries" is a timeout.
            if "No response received" in str(exc):
                return "timeout"
            return f"error {exc}"
        except ModbusException as exc:  # includes ConnectionException
            return f"error {exc}"
        except (ValueError, TypeError, struct.error) as exc:
            return f"error {exc}"
        if rsp is None:
            return "error no response object"
        # isError() tests function_code > 0x80, which misses an exception to
        # function 0 (pymodbus servers send 80 01 for undecodable requests).
        if isinstance(rsp, ExceptionResponse):
            return f"exception {rsp.exception_code}"
        return rsp

    async def run(self, tok: list[str]) -> str:
        """Run one command line (already split); return its result line."""
        cmd, args = tok[0], tok[1:]
        if cmd not in self.SYNTAX:
            return f"error unknown command: {cmd}"
        try:
            return await self.dispatch(cmd, args)
        except Usage:
            return f"error usage: {self.SYNTAX[cmd]}"

    async def dispatch(self, cmd: str, a: list[str]) -> str:  # noqa: C901, PLR0911, PLR0912
        """Map a command to a pymodbus call and format the answer."""
        c, dev = self.client, {"device_id": self.unit}

        def arity(n: int, at_least: bool = False) -> None:
            if (len(a) < n) if at_least else (len(a) != n):
                raise Usage

        if cmd == "unit":
            arity(1)
            self.unit = num(a[0], 0, 255)
            return "ok"
        if cmd == "sleep":
            arity(1)
            await asyncio.sleep(num(a[0], 0, 60000) / 1000)
            return "ok"

        if cmd in ("read_holding", "read_input", "read_coils", "read_discrete"):
            arity(2)
            addr, count = num(a[0]), num(a[1])
            fn = {
                "read_holding": c.read_holding_registers,
                "read_input": c.read_input_registers,
                "read_coils": c.read_coils,
                "read_discrete": c.read_discrete_inputs,
            }[cmd]
            rsp = await self.call(fn(addr, count=count, **dev))
            if isinstance(rsp, str):
                return rsp
            if cmd in ("read_coils", "read_discrete"):
                # Bits come back padded to a multiple of 8.
                return " ".join(["ok"] + [str(int(b)) for b in rsp.bits[:count]])
            return " ".join(["ok"] + [str(v) for v in rsp.registers])

        if cmd == "write_coil":
            arity(2)
            rsp = await self.call(c.write_coil(num(a[0]), bool(num(a[1], 0, 1)), **dev))
        elif cmd == "write_register":
            arity(2)
            rsp = await self.call(c.write_register(num(a[0]), num(a[1]), **dev))
        elif cmd == "write_coils":
            arity(2, at_least=True)
            bits = [bool(num(v, 0, 1)) for v in a[1:]]
            rsp = await self.call(c.write_coils(num(a[0]), bits, **dev))
        elif cmd == "write_registers":
            arity(2, at_least=True)
            values = [num(v) for v in a[1:]]
            rsp = await self.call(c.write_registers(num(a[0]), values, **dev))
        elif cmd == "mask_write":
            arity(3)
            rsp = await self.call(
                c.mask_write_register(
                    address=num(a[0]), and_mask=num(a[1]), or_mask=num(a[2]), **dev
                )
            )
        elif cmd == "write_read":
            arity(4, at_least=True)
            rsp = await self.call(
                c.readwrite_registers(
                    read_address=num(a[0]),
                    read_count=num(a[1]),
                    write_address=num(a[2]),
                    values=[num(v) for v in a[3:]],
                    **dev,
                )
            )
            if isinstance(rsp, str):
                return rsp
            return " ".join(["ok"] + [str(v) for v in rsp.registers])
        elif cmd == "report_slave_id":
            arity(0)
            rsp = await self.call(c.execute(False, ReportDeviceIdRequest(dev_id=self.unit)))
            if isinstance(rsp, str):
                return rsp
            return " ".join(["ok"] + [f"{b:02x}" for b in rsp.raw])
        elif cmd == "read_exception_status":
            arity(0)
            rsp = await self.call(c.read_exception_status(**dev))
            if isinstance(rsp, str):
                return rsp
            return f"ok {rsp.status}"
        elif cmd == "diag":
            arity(2)
            request = DiagnosticBase(message=num(a[1]), dev_id=self.unit)
            request.sub_function_code = num(a[0])
            rsp = await self.call(c.execute(False, request))
            if isinstance(rsp, str):
                return rsp
            msg = rsp.message
            if isinstance(msg, bytes):
                words = words_from_bytes(msg)
            elif isinstance(msg, int):
                words = [msg]
            else:
                words = list(msg or [])
            return " ".join(["ok", str(rsp.sub_function_code)] + [str(w) for w in words])
        elif cmd == "read_device_id":
            arity(2)
            rsp = await self.call(
                c.read_device_information(
                    read_code=num(a[0], 0, 255), object_id=num(a[1], 0, 255), **dev
                )
            )
            if isinstance(rsp, str):
                return rsp
            out = ["ok"]
            for oid, value in rsp.information.items():
                for item in value if isinstance(value, list) else [value]:
                    out.append(f"{oid:02x}={bytes(item).hex()}")
            return " ".join(out)
        elif cmd == "read_fifo":
            arity(1)
            rsp = await self.call(c.read_fifo_queue(address=num(a[0]), **dev))
            if isinstance(rsp, str):
                return rsp
            return " ".join(["ok"] + [str(v) for v in rsp.values])
        elif cmd == "read_file":
            arity(3)
            # FileRecord takes record_length in BYTES and halves it itself.
            record = FileRecord(
                file_number=num(a[0]), record_number=num(a[1]), record_length=2 * num(a[2], 0, 124)
            )
            rsp = await self.call(c.read_file_record([record], **dev))
            if isinstance(rsp, str):
                return rsp
            words: list[int] = []
            for rec in rsp.records:
                words.extend(words_from_bytes(rec.record_data))
            return " ".join(["ok"] + [str(w) for w in words])
        elif cmd == "write_file":
            arity(3, at_least=True)
            data = b"".join(struct.pack(">H", num(v)) for v in a[2:])
            record = FileRecord(file_number=num(a[0]), record_number=num(a[1]), record_data=data)
            rsp = await self.call(c.write_file_record([record], **dev))
        else:  # pragma: no cover - SYNTAX and dispatch agree
            return f"error unknown command: {cmd}"
        return rsp if isinstance(rsp, str) else "ok"


async def read_line() -> str:
    """Read one stdin line without blocking the event loop."""
    return await asyncio.get_running_loop().run_in_executor(None, sys.stdin.readline)


async def run_script(client, unit: int) -> int:
    """The script mode loop."""
    runner = Runner(client, unit)
    while True:
        line = await read_line()
        if not line:
            return 0
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        try:
            result = await runner.run(tok)
        except Exception as exc:  # noqa: BLE001 - a fixture must not die on one bad line
            result = f"error {type(exc).__name__}: {exc}"
        sys.stdout.write(result + "\n")
        sys.stdout.flush()


def percentile_us(sorted_ns: list[int], p: int) -> float:
    """Nearest-rank percentile, in microseconds."""
    n = len(sorted_ns)
    rank = min(n, max(1, -(-p * n // 100)))
    return sorted_ns[rank - 1] / 1000.0


async def run_bench(client, unit: int, count: int, address: int, quantity: int) -> int:
    """N back-to-back FC03 reads; one JSON line."""
    lat: list[int] = []
    errors = 0
    start = time.monotonic_ns()
    for _ in range(count):
        t0 = time.monotonic_ns()
        try:
            rsp = await client.read_holding_registers(address, count=quantity, device_id=unit)
            good = not isinstance(rsp, ExceptionResponse) and len(rsp.registers) == quantity
        except Exception:  # noqa: BLE001 - counted as an error
            good = False
        lat.append(time.monotonic_ns() - t0)
        errors += 0 if good else 1
    seconds = (time.monotonic_ns() - start) / 1e9
    usage = resource.getrusage(resource.RUSAGE_SELF)
    lat.sort()
    print(
        json.dumps(
            {
                "transactions": count,
                "errors": errors,
                "seconds": round(seconds, 6),
                "tps": round(count / seconds, 1) if seconds > 0 else 0.0,
                "p50_us": round(percentile_us(lat, 50), 1),
                "p99_us": round(percentile_us(lat, 99), 1),
                "user_s": round(usage.ru_utime, 6),
                "sys_s": round(usage.ru_stime, 6),
            },
            separators=(",", ":"),
        ),
        flush=True,
    )
    return 0


def make_client(args, parity: str):
    """Build (not connect) the pymodbus async client."""
    timeout = args.timeout_ms / 1000
    if args.rtu:
        client = AsyncModbusSerialClient(
            args.rtu,
            baudrate=args.baud,
            bytesize=args.data_bits,
            parity=parity,
            stopbits=args.stop_bits,
            timeout=timeout,
            retries=0,
        )
    elif args.tls:
        # Modbus/TCP Security: trust --ca, show --cert/--key if given.
        host, port = args.tls
        sslctx = ssl.create_default_context(ssl.Purpose.SERVER_AUTH, cafile=args.ca)
        if args.cert:
            sslctx.load_cert_chain(args.cert, args.key)
        client = AsyncModbusTlsClient(host, port=port, sslctx=sslctx, timeout=timeout, retries=0)
    else:
        host, port = args.tcp
        client = AsyncModbusTcpClient(host, port=port, timeout=timeout, retries=0)
    client.register(RawReportServerIdResponse)
    # Otherwise pymodbus closes a TCP connection after retries+3 silent requests.
    client.set_max_no_responses(1 << 30)
    return client


async def connect(args, parity: str):
    """Connect; return (client, None) or (None, reason)."""
    client = make_client(args, parity)
    try:
        if await client.connect():
            return client, None
        reason = "connect() returned False"
    except Exception as exc:  # noqa: BLE001 - termios.error is not an OSError
        reason = repr(exc)
    # Drop every reference to the half-open port (see pymodbus_server.py):
    # its exclusive flock() would make the retry fail.
    client.close()
    del client
    gc.collect()
    return None, reason


async def run(args) -> int:
    """Connect and run the selected mode."""
    client, reason = await connect(args, args.parity)
    # Only the pty parity failure (termios.error EINVAL) falls back; a missing
    # or busy port is an error whatever the parity.
    if client is None and args.rtu and args.parity != "N" and "(22," in str(reason):
        note(
            f"cannot open {args.rtu} with parity {args.parity} ({reason}); "
            "pyserial cannot set parity on a pty - falling back to parity N"
        )
        client, reason = await connect(args, "N")
    if client is None:
        where = args.rtu or "{}:{}".format(*args.tcp)
        note(f"cannot connect to {where}: {reason}")
        return 1
    try:
        if args.mode == "script":
            return await run_script(client, args.unit)
        return await run_bench(client, args.unit, args.count, args.address, args.quantity)
    finally:
        client.close()


def host_port(text: str) -> tuple[str, int]:
    """argparse type: HOST:PORT ([v6]:PORT allowed)."""
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise argparse.ArgumentTypeError("expected HOST:PORT")
    if host.startswith("[") and host.endswith("]"):
        host = host[1:-1]
    try:
        value = int(port)
    except ValueError:
        value = 0
    if not 1 <= value <= 65535:
        raise argparse.ArgumentTypeError("port must be 1..65535")
    return host, value


def ranged(lo: int, hi: int):
    """argparse type factory: an int in [lo, hi]."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = lo - 1
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be {lo}..{hi}")
        return value

    return parse


def parse_args(argv):
    """Parse the command line; argparse exits 2 with usage on errors."""
    parser = argparse.ArgumentParser(
        prog="pymodbus_client.py",
        description="pymodbus client fixture: 'script' runs commands from stdin, "
        "'bench' times N FC03 reads (see tests/peers/README.md).",
    )
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--rtu", metavar="PATH", help="serial device (e.g. a socat pty link)")
    where.add_argument("--tcp", metavar="HOST:PORT", type=host_port)
    where.add_argument("--tls", metavar="HOST:PORT", type=host_port, help="Modbus/TCP Security")
    parser.add_argument("--ca", metavar="FILE", help="--tls: the CA of the server's certificate")
    parser.add_argument("--cert", metavar="FILE", help="--tls: our certificate")
    parser.add_argument("--key", metavar="FILE", help="--tls: the key of --cert")
    parser.add_argument("--baud", type=ranged(50, 4000000), default=19200)
    parser.add_argument("--parity", choices=["N", "E", "O"], default="N")
    parser.add_argument("--data-bits", type=int, choices=[5, 6, 7, 8], default=8)
    parser.add_argument("--stop-bits", type=int, choices=[1, 2], default=1)
    parser.add_argument("--unit", type=ranged(0, 255), default=1)
    parser.add_argument("--timeout-ms", type=ranged(1, 600000), default=1000)
    parser.add_argument("--debug", action="store_true", help="pymodbus debug log on stderr")
    parser.add_argument("mode", choices=["script", "bench"])
    parser.add_argument("--count", type=ranged(1, 100000000), help="bench: number of reads")
    parser.add_argument("--address", type=ranged(0, 65535), default=0, help="bench (default 0)")
    parser.add_argument("--quantity", type=ranged(1, 125), default=10, help="bench (default 10)")
    args = parser.parse_args(argv)
    if args.tls and not args.ca:
        parser.error("--tls needs --ca")
    if bool(args.cert) != bool(args.key):
        parser.error("--cert and --key go together")
    if args.mode == "bench" and args.count is None:
        parser.error("bench needs --count N")
    if args.mode == "script" and args.count is not None:
        parser.error("--count is for bench mode")
    return args


def main(argv=None) -> int:
    """Entry point."""
    args = parse_args(sys.argv[1:] if argv is None else argv)
    if args.debug:
        pymodbus.pymodbus_apply_logging_config(logging.DEBUG)
    else:
        # Timeouts are reported on stdout; pymodbus would also log them.
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    return asyncio.run(run(args))


if __name__ == "__main__":
    sys.exit(main())
