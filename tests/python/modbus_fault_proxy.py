#!/usr/bin/env python3
"""A Modbus TCP proxy written with pymodbus that injects faults on command:
the independent peer between the daemon and a device in the bus-metrics
test.

    modbus_fault_proxy.py UPSTREAM_HOST UPSTREAM_PORT
        # binds 127.0.0.1 port 0, prints "READY <port>"

Every request is forwarded with a pymodbus client to the upstream device
(same unit id, function and addresses) and its answer returned, until a
line on standard input asks for faults:

    timeout N   the next N requests get no answer at all (the client's
                deadline passes)
    busy N      the next N requests are answered with exception 6
                (server device busy) without reaching the device

A request after an injected fault is always forwarded, so a client that
retries once gets through. After the last fault of a command the proxy
prints "INJECTED <kind> <N>". The proxy stops when its standard input
closes.
"""
import asyncio
import sys

from pymodbus.client import AsyncModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.datastore import ModbusServerContext
from pymodbus.exceptions import NoSuchIdException
from pymodbus.server import ModbusTcpServer


class Faults:
    """Faults waiting to be injected, one per request, never two in a row."""

    def __init__(self):
        self.queue = []  # kinds, in order
        self.last_faulted = False
        self.done = {}

    def add(self, kind, n):
        self.queue.extend([kind] * n)
        self.done[kind] = 0

    def next(self):
        if not self.queue or self.last_faulted:
            self.last_faulted = False
            return None
        kind = self.queue.pop(0)
        self.last_faulted = True
        self.done[kind] += 1
        if kind not in self.queue:
            print(f"INJECTED {kind} {self.done[kind]}", flush=True)
        return kind


class ForwardingContext(ModbusServerContext):
    """A server context that forwards to the upstream device, or injects
    the next fault. pymodbus serves a context marked `old_simulator`
    through its `async_getValues` / `async_setValues` as they are."""

    def __init__(self, upstream, faults):  # pylint: disable=super-init-not-called
        self.old_simulator = True
        self.simdevices = []
        self.upstream = upstream
        self.faults = faults

    def device_ids(self):
        return list(range(1, 248))

    def _fault(self):
        kind = self.faults.next()
        if kind == "timeout":
            # With ignore_missing_devices the server sends no answer.
            raise NoSuchIdException("injected: no answer")
        if kind == "busy":
            return ExcCodes.DEVICE_BUSY
        return None

    async def async_getValues(self, device_id, func_code, address, count=1):
        c = self.upstream
        call = {
            1: c.read_coils,
            2: c.read_discrete_inputs,
            3: c.read_holding_registers,
            4: c.read_input_registers,
        }.get(func_code)
        if call is None:
            # A write's read-back (functions 5, 6, 15, 16), within the
            # request the write began: what was written.
            return self.written[:count]
        fault = self._fault()
        if fault is not None:
            return fault
        r = await call(address, count=count, device_id=device_id)
        if r.isError():
            return ExcCodes(r.exception_code)
        return r.bits[:count] if func_code in (1, 2) else r.registers

    async def async_setValues(self, device_id, func_code, address, values):
        fault = self._fault()
        if fault is not None:
            return fault
        c = self.upstream
        if func_code in (5, 15):
            r = await c.write_coils(address, list(values), device_id=device_id)
        else:
            r = await c.write_registers(address, list(values), device_id=device_id)
        self.written = list(values)
        if r.isError():
            return ExcCodes(r.exception_code)
        return None


async def read_commands(faults):
    loop = asyncio.get_running_loop()
    while True:
        line = await loop.run_in_executor(None, sys.stdin.readline)
        if not line:
            return
        kind, n = line.split()
        if kind not in ("timeout", "busy"):
            sys.exit(f"unknown fault {kind}")
        faults.add(kind, int(n))


async def main():
    host, port = sys.argv[1], int(sys.argv[2])
    upstream = AsyncModbusTcpClient(host, port=port, timeout=2, retries=0)
    if not await upstream.connect():
        sys.exit(f"cannot reach the upstream device at {host}:{port}")
    faults = Faults()
    server = ModbusTcpServer(
        ForwardingContext(upstream, faults),
        address=("127.0.0.1", 0),
        ignore_missing_devices=True,
    )
    await server.serve_forever(background=True)
    print(f"READY {server.transport.sockets[0].getsockname()[1]}", flush=True)
    await read_commands(faults)
    await server.shutdown()
    upstream.close()


if __name__ == "__main__":
    asyncio.run(main())
