"""The Python peer of motorbench's recorder: the same sample messages in the
contract layout, written with the `mcap` package's writer (zstd chunks of
1 MiB, the library's defaults; its summary and indexes).

The declarations (header, `motorbench.test` metadata, schemas, channels
with their metadata) are copied from a file motorbench wrote, so the layout
is the contract's; the clock then times writing every sample message,
`{"value": <f64>}` as JSON, `log_time` = start + t, sequence numbers per
channel, and finishing the file.

Usage: mcap_write.py reference.mcap out.mcap samples; prints one JSON line.
"""

import json
import math
import sys
import time

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer


def sample_value(k, c):
    """Channel c at sample k: motorbench's `sample_value`, digit for digit."""
    t = k * 5e-4
    base = [12.5, 0.75, 104.0, 48.0][c]
    v = base * (1.0 + 0.3 * math.sin(t * (1.0 + c))) * 1000.0
    # Rust's f64::round: half away from zero.
    return math.copysign(math.floor(abs(v) + 0.5), v) / 1000.0


def main():
    reference, out, samples = sys.argv[1], sys.argv[2], int(sys.argv[3])
    with open(reference, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
    start_ns = int(metadata[0][1]["start_time_ns"])
    clock = time.perf_counter()
    with open(out, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile=header.profile, library=header.library)
        for name, md in metadata:
            w.add_metadata(name, md)
        schema_ids = {}
        for sid, s in summary.schemas.items():
            schema_ids[sid] = w.register_schema(s.name, s.encoding, s.data)
        sample_channels = []
        for cid, c in summary.channels.items():
            new = w.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], c.metadata)
            if c.topic.startswith("/sensor/"):
                sample_channels.append(new)
        n = len(sample_channels)
        for k in range(samples // n):
            t = start_ns + k * 500_000
            for c, channel in enumerate(sample_channels):
                w.add_message(
                    channel,
                    log_time=t,
                    publish_time=t,
                    data=json.dumps({"value": sample_value(k, c)}).encode(),
                    sequence=k,
                )
        w.finish()
    seconds = time.perf_counter() - clock
    print(json.dumps({"seconds": seconds, "samples": (samples // n) * n}))


if __name__ == "__main__":
    main()
