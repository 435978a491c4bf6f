#!/usr/bin/env node
// encode.js - a Sparkplug B payload encoded by Eclipse Tahu's JavaScript codec (npm
// sparkplug-payload 1.0.3): a DCMD as a Tahu (or Ignition) host application sends one.
//
//     node encode.js [FILE|-] > payload.bin
//
// Reads one JSON object from FILE, or stdin when FILE is '-' or absent, in Tahu's own shape,
// and writes Tahu's encodePayload of it, the raw protobuf bytes, to stdout:
//
//     {"timestamp": "1700000000000",
//      "metrics": [{"name": "F001", "alias": "1", "type": "UInt32", "value": 50,
//                   "timestamp": "1700000000000"}]}
//
// `type` is a Sparkplug datatype name as Tahu spells it (Int8 ... UInt32, UInt64, Float, Double,
// Boolean, String, DateTime, ...); Tahu chooses the field: Int8/16/32 and UInt8/16 in int_value,
// UInt32, Int64, UInt64 and DateTime in long_value. A value of null sends is_null. 64-bit
// numbers may be given as decimal strings (JSON numbers lose precision past 2^53): the
// payload's and the metrics' timestamp, seq, alias, and the value of a long_value type.
//
// Exit status 0 when Tahu encoded the payload; 1 with "error: ..." on stderr when the JSON is
// bad or Tahu threw.

"use strict";

const fs = require("fs");
const Long = require("long");
const { encodePayload } = require("sparkplug-payload/lib/sparkplugbpayload");

/** The datatypes Tahu writes to long_value, and whether their values are signed. */
const LONG_VALUE_SIGNED = { INT64: true, UINT32: false, UINT64: false, DATETIME: false };

/** A decimal string as a Long (a JSON number as it is). */
function long(value, signed) {
    if (typeof value !== "string") {
        return value;
    }
    if (!/^-?[0-9]+$/.test(value)) {
        throw new Error(`"${value}" is not a decimal integer`);
    }
    return Long.fromString(value, !signed);
}

function metric(m) {
    const out = { ...m };
    for (const key of ["timestamp", "alias"]) {
        if (out[key] !== undefined && out[key] !== null) {
            out[key] = long(out[key], false);
        }
    }
    const type = typeof out.type === "string" ? out.type.toUpperCase() : "";
    if (type in LONG_VALUE_SIGNED && out.value !== undefined && out.value !== null) {
        out.value = long(out.value, LONG_VALUE_SIGNED[type]);
    }
    return out;
}

function payload(p) {
    if (p === null || typeof p !== "object" || Array.isArray(p)) {
        throw new Error("the payload must be a JSON object");
    }
    const out = { ...p };
    for (const key of ["timestamp", "seq"]) {
        if (out[key] !== undefined && out[key] !== null) {
            out[key] = long(out[key], false);
        }
    }
    if (out.metrics !== undefined && out.metrics !== null) {
        if (!Array.isArray(out.metrics)) {
            throw new Error("metrics must be an array");
        }
        out.metrics = out.metrics.map(metric);
    }
    return out;
}

function main(args) {
    if (args.length > 1 || args[0] === "-h" || args[0] === "--help") {
        process.stderr.write("usage: node encode.js [FILE|-] > payload.bin\n");
        return 2;
    }
    const file = args[0] === undefined || args[0] === "-" ? 0 : args[0];
    let bytes;
    try {
        bytes = encodePayload(payload(JSON.parse(fs.readFileSync(file, "utf8"))));
    } catch (e) {
        process.stderr.write(`error: ${e.message}\n`);
        return 1;
    }
    process.stdout.write(Buffer.from(bytes));
    return 0;
}

process.exitCode = main(process.argv.slice(2));
