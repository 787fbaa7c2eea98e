"""The Python peer of motorbench's record reader: every message of a record
read with the `mcap` package and its JSON payload decoded with json.loads.

Usage: mcap_read.py record.mcap; prints one JSON line: the time, the number
of sample messages and the sum of their values (file order), which
motorbench's reader must match.
"""

import json
import sys
import time

from mcap.reader import make_reader


def main():
    path = sys.argv[1]
    with open(path, "rb") as f:
        f.read()  # the page cache warmed outside the clock, as on motorbench's side
    clock = time.perf_counter()
    count, total, others = 0, 0.0, 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            payload = json.loads(message.data)
            if channel.topic.startswith("/sensor/") or channel.topic.startswith("/command/"):
                count += 1
                total += payload["value"]
            else:
                others += 1
    seconds = time.perf_counter() - clock
    print(json.dumps({"seconds": seconds, "samples": count, "sum": total, "others": others}))


if __name__ == "__main__":
    main()
