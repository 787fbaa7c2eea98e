#!/usr/bin/env python3
"""A streaming sensor written with pyserial: the independent peer of the
Rust serial protocol tests. It encodes records from the protocol's written
definition (drivers/src/serial/{ascii,binary}.rs), not from the Rust code.

    serial_peer.py PATH ascii|binary COUNT [--garbage] [--skip N] [--hold]

Opens PATH (a pseudo-terminal) at 115200 8N1 and writes COUNT records:
seq k (from 1), t_us = 1_000_000 + 500 k, values u = 0.5 k, i = -k / 1000,
n = k * 1000003 (an integer beyond f32 precision). With --garbage, noise
and a corrupted copy of a record go out before every tenth record. With
--skip N the record with seq N is never sent. Prints "DONE <count>" and,
with --hold, keeps the port open until its standard input closes.
"""
import binascii
import struct
import sys

import serial


def values(k):
    return [("u", 0.5 * k), ("i", -k / 1000.0), ("n", float(k * 1000003))]


def ascii_record(k):
    body = f"MB,{k},{1_000_000 + 500 * k}," + ",".join(
        f"{name}={value!r}" for name, value in values(k)
    )
    checksum = 0
    for b in body.encode():
        checksum ^= b
    return f"${body}*{checksum:02X}\r\n".encode()


def cobs_encode(data):
    out = bytearray()
    block = bytearray()
    for b in data:
        if b == 0:
            out.append(len(block) + 1)
            out += block
            block = bytearray()
        else:
            block.append(b)
            if len(block) == 254:
                out.append(255)
                out += block
                block = bytearray()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


def binary_record(k):
    vals = values(k)
    raw = struct.pack("<BIQB", 0xB1, k, 1_000_000 + 500 * k, len(vals))
    raw += b"".join(struct.pack("<d", v) for _, v in vals)
    raw += struct.pack("<H", binascii.crc_hqx(raw, 0xFFFF))
    return cobs_encode(raw) + b"\x00"


def main():
    path, framing, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
    garbage = "--garbage" in sys.argv
    skip = int(sys.argv[sys.argv.index("--skip") + 1]) if "--skip" in sys.argv else None
    encode = ascii_record if framing == "ascii" else binary_record
    port = serial.Serial(path, 115200, timeout=1)
    if framing == "binary":
        port.write(b"\x00")  # a delimiter first, so the receiver syncs
    for k in range(1, count + 1):
        if garbage and k % 10 == 0:
            bad = bytearray(encode(k))
            bad[len(bad) // 2] ^= 0x20 if bad[len(bad) // 2] != 0x20 else 0x21
            port.write(b"\xffnoise\x01" + bytes(bad))
        if k != skip:
            port.write(encode(k))
    port.flush()
    print(f"DONE {count}", flush=True)
    if "--hold" in sys.argv:
        sys.stdin.read()
    port.close()


if __name__ == "__main__":
    main()
