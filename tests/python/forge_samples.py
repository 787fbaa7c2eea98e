#!/usr/bin/env python3
"""Copy an MCAP file with some sample payloads replaced, to show that
check_mcap.py refuses them (tests/e2e/record_v2.rs).

Everything is copied as it is (header, schemas, channels, metadata, every
message with its times), except the payloads of the first messages on
/sensor/ channels, which become, in turn, each of FORGED.

Usage: python3 forge_samples.py IN.mcap OUT.mcap
"""

import sys

from mcap.reader import make_reader
from mcap.writer import Writer

# What a sample must not be: a boolean, an extra key, a missing value,
# NaN (not JSON), a string.
FORGED = [
    b'{"value":true}',
    b'{"value":1.5,"unit":"V"}',
    b"{}",
    b'{"value":NaN}',
    b'{"value":"7"}',
]


def main(src, dst):
    with open(src, "rb") as f_in, open(dst, "wb") as f_out:
        reader = make_reader(f_in)
        header = reader.get_header()
        summary = reader.get_summary()
        writer = Writer(f_out)
        writer.start(profile=header.profile, library=header.library)
        schema_ids = {}
        for sid, schema in sorted(summary.schemas.items()):
            schema_ids[sid] = writer.register_schema(
                name=schema.name, encoding=schema.encoding, data=schema.data
            )
        channel_ids = {}
        for cid, ch in sorted(summary.channels.items()):
            channel_ids[cid] = writer.register_channel(
                topic=ch.topic,
                message_encoding=ch.message_encoding,
                schema_id=schema_ids.get(ch.schema_id, 0),
                metadata=dict(ch.metadata),
            )
        for m in reader.iter_metadata():
            writer.add_metadata(name=m.name, data=dict(m.metadata))
        forged = list(FORGED)
        for _schema, channel, message in reader.iter_messages(log_time_order=True):
            data = message.data
            if forged and channel.topic.startswith("/sensor/"):
                data = forged.pop(0)
            writer.add_message(
                channel_id=channel_ids[channel.id],
                log_time=message.log_time,
                publish_time=message.publish_time,
                sequence=message.sequence,
                data=data,
            )
        writer.finish()
    if forged:
        sys.exit(f"only {len(FORGED) - len(forged)} samples to forge in {src}")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
