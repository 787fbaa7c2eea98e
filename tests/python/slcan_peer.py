#!/usr/bin/env python3
"""The other end of an SLCAN link, written with python-can's slcan
interface: the independent peer of the Rust SLCAN tests.

    slcan_peer.py PATH echo         # answer every frame with id + 1, same data
    slcan_peer.py PATH burst COUNT  # send COUNT frames (id 0x181, 8 bytes)

python-can plays the host side of the Lawicel protocol (it sends `O` and
frames, as to a USB-CAN adapter); a host on each end of a pseudo-terminal
exchange frames in the same text form. Prints "READY" once the bus is open,
then "DONE <n>" in burst mode; in echo mode it runs until its standard
input closes.
"""
import sys
import threading

import can


def main():
    path, mode = sys.argv[1], sys.argv[2]
    bus = can.Bus(interface="slcan", channel=path, tty_baudrate=115200, sleep_after_open=0)
    print("READY", flush=True)
    if mode == "burst":
        count = int(sys.argv[3])
        for k in range(count):
            data = k.to_bytes(4, "little") + bytes([0xA5, 0x5A, 0x00, 0xFF])
            bus.send(can.Message(arbitration_id=0x181, data=data, is_extended_id=False))
        print(f"DONE {count}", flush=True)
        sys.stdin.read()
    else:
        stop = threading.Event()
        threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
        while not stop.is_set():
            msg = bus.recv(timeout=0.05)
            if msg is None or msg.is_error_frame:
                continue
            reply = can.Message(
                arbitration_id=msg.arbitration_id + 1,
                data=msg.data,
                is_extended_id=msg.is_extended_id,
                is_remote_frame=msg.is_remote_frame,
                dlc=msg.dlc,
            )
            bus.send(reply)
    bus.shutdown()


if __name__ == "__main__":
    main()
