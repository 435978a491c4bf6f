#!/usr/bin/env node
// decode.js - what Eclipse Tahu's JavaScript codec (npm sparkplug-payload 1.0.3) makes of a
// Sparkplug B payload, as JSON.
//
//     node decode.js [FILE|-]
//
// The payload is read from FILE, or stdin when FILE is '-' or absent, and given to Tahu's
// decodePayload as it is: no birth context, so an alias-only metric has no name and, its
// datatype unknown, a null value (Tahu decodes each payload on its own, as it is used).
//
// Prints one JSON object on stdout, Tahu's decoded payload with its own field names:
//
//     {"timestamp": "1700000000000", "seq": "1",
//      "metrics": [{"name": "F001", "alias": "1", "type": "UInt16", "value": 5000,
//                   "timestamp": "1700000000000",
//                   "properties": {"engUnit": {"type": "String", "value": "Hz"}}}]}
//
// Values: every Long (protobuf uint64 fields, and Int64/UInt64/DateTime values) as its decimal
// string, signed or unsigned as Tahu made it; bytes as lowercase hex; NaN and infinities as the
// strings "NaN", "inf", "-inf"; a value Tahu left undefined as null. Fields Tahu did not set
// are absent.
//
// Exit status 0 when Tahu decoded the payload; 1 with "error: ..." on stderr when it threw.
//
// Tahu behaviour worth knowing (lib/sparkplugbpayload.js, getValue):
//   * UInt32 is read from long_value only; one in int_value, as the specification puts it, is
//     null.
//   * UInt8 and UInt16 are read from int_value only.
//   * Int8/16/32 are read from int_value as a signed 32-bit number: a 32-bit sign extension
//     (4294967291) is -5, two's complement of the type's own width (Int16 65531) stays 65531.

"use strict";

const fs = require("fs");
const Long = require("long");
const { decodePayload } = require("sparkplug-payload/lib/sparkplugbpayload");

/** Tahu's decoded value made JSON: Longs as strings, bytes as hex, non-finite floats named. */
function plain(value) {
    if (value === undefined || value === null) {
        return null;
    }
    if (Long.isLong(value)) {
        return value.toString();
    }
    if (value instanceof Uint8Array) {
        return Buffer.from(value).toString("hex");
    }
    if (typeof value === "number" && !Number.isFinite(value)) {
        if (Number.isNaN(value)) {
            return "NaN";
        }
        return value > 0 ? "inf" : "-inf";
    }
    if (Array.isArray(value)) {
        return value.map(plain);
    }
    if (typeof value === "object") {
        const out = {};
        for (const [key, field] of Object.entries(value)) {
            out[key] = plain(field);
        }
        return out;
    }
    return value;
}

function main(args) {
    if (args.length > 1 || args[0] === "-h" || args[0] === "--help") {
        process.stderr.write("usage: node decode.js [FILE|-]\n");
        return 2;
    }
    const file = args[0] === undefined || args[0] === "-" ? 0 : args[0];
    let decoded;
    try {
        decoded = decodePayload(fs.readFileSync(file));
    } catch (e) {
        process.stderr.write(`error: ${e.message}\n`);
        return 1;
    }
    process.stdout.write(JSON.stringify(plain(decoded)) + "\n");
    return 0;
}

process.exitCode = main(process.argv.slice(2));
