#!/usr/bin/env python3
"""python-can's slcan interface at full speed on a pseudo-terminal: the
other half of `cargo bench --bench links_slcan_vs_python`.

    links_slcan_python.py PATH recv COUNT   # receive COUNT frames
    links_slcan_python.py PATH send COUNT   # send COUNT frames (id 0x181, 8 bytes)

Prints "READY" once the bus is open; in recv mode then "RATE <frames/s>"
measured from the first frame received to the COUNT-th on this process's
monotonic clock. In send mode it sends COUNT frames as fast as bus.send
returns, prints "SENT", and waits for its standard input to close.
"""
import sys
import time

import can


def main():
    path, mode, count = sys.argv[1], sys.argv[2], int(sys.argv[3])
    bus = can.Bus(interface="slcan", channel=path, tty_baudrate=115200, sleep_after_open=0)
    print("READY", flush=True)
    if mode == "recv":
        got = 0
        first = None
        while got < count:
            msg = bus.recv(timeout=5.0)
            if msg is None:
                print(f"TIMEOUT after {got} frames", flush=True)
                break
            if msg.is_error_frame:
                continue
            if first is None:
                first = time.monotonic()
            got += 1
        elapsed = time.monotonic() - first if first is not None else 0.0
        if got == count and elapsed > 0:
            print(f"RATE {(count - 1) / elapsed:.1f}", flush=True)
    else:
        msg = can.Message(arbitration_id=0x181, data=bytes(range(8)), is_extended_id=False)
        for _ in range(count):
            bus.send(msg)
        print("SENT", flush=True)
        sys.stdin.read()
    bus.shutdown()


if __name__ == "__main__":
    main()
