#!/usr/bin/env python3
"""A Modbus server written with pymodbus: the independent peer of the
Rust Modbus client tests.

    modbus_peer.py tcp            # binds 127.0.0.1 port 0, prints "READY <port>"
    modbus_peer.py rtu PATH BAUD  # serves RTU on a serial path, prints "READY <path>"

Unit id 1. Holding registers 0..31 hold an RD6006-like supply (register 0 =
60062, the rest 0); input registers 0..9 hold two IEEE 754 floats, 230.5 at
0-1 and -1.25 at 2-3, high word first. Addresses outside answer with
exception 2 (illegal data address); requests to other unit ids get no
answer when pymodbus manages to (3.16.1 answers exception 4 instead). The server stops when its standard
input closes.
"""
import asyncio
import struct
import sys

from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusSerialServer, ModbusTcpServer


def words_of_float(value):
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return [hi, lo]


def context():
    holding = [0] * 32
    holding[0] = 60062
    inputs = words_of_float(230.5) + words_of_float(-1.25) + [0] * 6
    # pymodbus maps protocol address a to data block index a + 1 for its
    # device contexts, so blocks start at 1 to serve protocol address 0.
    device = ModbusDeviceContext(
        hr=ModbusSequentialDataBlock(1, holding),
        ir=ModbusSequentialDataBlock(1, inputs),
    )
    return ModbusServerContext(devices={1: device}, single=False)


async def wait_for_stdin_close():
    loop = asyncio.get_running_loop()
    await loop.run_in_executor(None, sys.stdin.read)


async def main():
    mode = sys.argv[1]
    if mode == "tcp":
        server = ModbusTcpServer(context(), address=("127.0.0.1", 0), ignore_missing_devices=True)
        await server.serve_forever(background=True)
        port = server.transport.sockets[0].getsockname()[1]
        print(f"READY {port}", flush=True)
    elif mode == "rtu":
        path, baud = sys.argv[2], int(sys.argv[3])
        server = ModbusSerialServer(
            context(), port=path, baudrate=baud, ignore_missing_devices=True
        )
        await server.serve_forever(background=True)
        print(f"READY {path}", flush=True)
    else:
        sys.exit(f"unknown mode {mode}")
    await wait_for_stdin_close()
    await server.shutdown()


if __name__ == "__main__":
    asyncio.run(main())
