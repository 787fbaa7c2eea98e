#!/usr/bin/env python3
"""Check that an MCAP file follows the motorbench data contract (version 1 or 2).

An independent reader (the PyPI `mcap` package, pinned in requirements.txt)
checks what the Rust recorder wrote:

- header: profile "" and library "motorbench/<version>";
- the `motorbench.test` metadata record with all its keys, schema_version "1"
  or "2"; version 2 adds `start_time_ns`, the same instant as `started_at`;
- version 1: log_time counts from the start of the test; version 2: log_time
  is wall-clock Unix time in ns, no message before `start_time_ns`;
- every channel: message encoding "json", a schema with encoding
  "jsonschema" whose data parses as JSON, the contract's schema name;
  /sensor/ and /command/ channels carry unit, quantity and source metadata
  and their topic is the prefix plus the quantity;
- every message: log_time == publish_time, the payload is JSON with the
  shape of its schema (Sample value a number; Segment and Event fields and
  enums; version 2 events in the shape of `foxglove.Log`, its timestamp the
  message's log_time; ...);
- segment start/end markers pair up;
- chunks are zstd-compressed (from the summary's chunk indexes);
- message counts agree with the summary statistics and with any
  --expect-topic TOPIC=COUNT given.

Prints a summary; the last line on stdout is a JSON object of message
counts per topic. On any failure prints the problems to stderr and exits 1.

Usage: python3 check_mcap.py FILE.mcap [--expect-topic TOPIC=COUNT ...]
"""

import argparse
import calendar
import datetime
import json
import re
import sys

from mcap.reader import make_reader

METADATA_NAME = "motorbench.test"
METADATA_KEYS = ("schema_version", "kind", "motor_id", "started_at", "nameplate", "config")
VERSIONS = ("1", "2")
# Foxglove's log levels motorbench writes in version 2: INFO, WARNING, ERROR.
LOG_LEVELS = (2, 3, 4)
KINDS = ("dc_step", "dc_coastdown", "im_slip_sweep")
# motorbench's additive extension: the induction machine's standard tests,
# segment kinds and the tests of /bench/standard_test (docs/data-contract.md).
STANDARD_TESTS = ("im_dc_resistance", "im_no_load", "im_locked_rotor")
SEGMENT_KINDS = KINDS + STANDARD_TESTS
PHASES = ("start", "end")
LEVELS = ("info", "warn", "abort")
BENCH_SCHEMAS = {
    "/bench/segment": "motorbench.Segment",
    "/bench/operating_point": "motorbench.OperatingPoint",
    "/bench/event": "motorbench.Event",
    "/bench/result": "motorbench.Result",
    # motorbench's additive extension: where the supply did not follow its
    # set point (docs/connect-your-rig.md).
    "/bench/supply_limit": "motorbench.SupplyLimit",
    # ... and the induction machine's standard-test readings.
    "/bench/standard_test": "motorbench.StandardTest",
}
SUPPLY_LIMIT_KINDS = ("current_limit", "voltage_compliance")
SAMPLE_SCHEMA = "motorbench.Sample"
SAMPLE_PREFIXES = ("/sensor/", "/command/")
RFC3339 = re.compile(
    r"^\d{4}-\d{2}-\d{2}[Tt ]\d{2}:\d{2}:\d{2}(\.\d+)?([Zz]|[+-]\d{2}:\d{2})$"
)
MAX_REPORTED = 20
MAGIC = b"\x89MCAP0\r\n"


class Failures:
    """Collects problems; only the first few per kind are kept in full."""

    def __init__(self):
        self.items = []
        self.dropped = 0

    def add(self, text):
        if len(self.items) < MAX_REPORTED:
            self.items.append(text)
        else:
            self.dropped += 1

    def __bool__(self):
        return bool(self.items)


def _reject_constant(token):
    raise ValueError(f"{token} is not JSON")


# One decoder for every message: `json.loads` with a keyword argument
# builds a new decoder per call, a fifth of the time of a large record.
_STRICT = json.JSONDecoder(parse_constant=_reject_constant)


def strict_json(data):
    """Parse JSON text, refusing NaN and Infinity (not JSON)."""
    if isinstance(data, (bytes, bytearray, memoryview)):
        data = bytes(data).decode("utf-8")
    return _STRICT.decode(data)


def is_number(v):
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def is_int(v):
    return isinstance(v, int) and not isinstance(v, bool)


def rfc3339_ns(text):
    """Unix time in ns of an RFC 3339 UTC time with up to 9 fractional digits."""
    m = re.match(r"^(\d{4}-\d{2}-\d{2}T\d{2}:\d{2}:\d{2})(?:\.(\d{1,9}))?(?:Z|\+00:00)$", text)
    if not m:
        raise ValueError(f"{text!r} is not an RFC 3339 UTC time")
    whole = datetime.datetime.strptime(m.group(1), "%Y-%m-%dT%H:%M:%S")
    seconds = calendar.timegm(whole.timetuple())
    return seconds * 1_000_000_000 + int((m.group(2) or "").ljust(9, "0"))


def shape_problem(schema_name, msg):
    """What is wrong with a decoded message for its schema, or None."""
    if not isinstance(msg, dict):
        return "not a JSON object"
    if schema_name == SAMPLE_SCHEMA:
        # The bulk of every record: tested without building a set.
        if len(msg) != 1 or "value" not in msg:
            return f"keys {sorted(msg)}, want ['value']"
        if type(msg["value"]) not in (int, float):  # bool is neither
            return f"value {msg['value']!r} is not a number"
        return None
    if schema_name == "motorbench.Segment":
        if set(msg) != {"index", "kind", "phase", "label"}:
            return f"keys {sorted(msg)}, want ['index', 'kind', 'label', 'phase']"
        if not is_int(msg["index"]) or msg["index"] < 0:
            return f"index {msg['index']!r} is not a non-negative integer"
        if msg["kind"] not in SEGMENT_KINDS:
            return f"kind {msg['kind']!r} is not one of {SEGMENT_KINDS}"
        if msg["phase"] not in PHASES:
            return f"phase {msg['phase']!r} is not one of {PHASES}"
        if not isinstance(msg["label"], str):
            return "label is not a string"
        return None
    if schema_name == "motorbench.Event":
        if set(msg) != {"level", "message"}:
            return f"keys {sorted(msg)}, want ['level', 'message']"
        if msg["level"] not in LEVELS:
            return f"level {msg['level']!r} is not one of {LEVELS}"
        if not isinstance(msg["message"], str):
            return "message is not a string"
        return None
    if schema_name == "foxglove.Log":
        keys = {"timestamp", "level", "message", "name", "file", "line"}
        if not keys <= set(msg):
            return f"keys {sorted(msg)}, want at least {sorted(keys)}"
        ts = msg["timestamp"]
        if not (isinstance(ts, dict) and is_int(ts.get("sec")) and is_int(ts.get("nsec"))
                and 0 <= ts["nsec"] < 1_000_000_000):
            return f"timestamp {ts!r} is not {{sec, nsec}}"
        if msg["level"] not in LOG_LEVELS:
            return f"level {msg['level']!r} is not one of {LOG_LEVELS}"
        for k in ("message", "name", "file"):
            if not isinstance(msg[k], str):
                return f"{k} is not a string"
        if not is_int(msg["line"]):
            return "line is not an integer"
        return None
    if schema_name == "motorbench.OperatingPoint":
        keys = {"segment", "slip", "line_voltage", "line_current", "input_power",
                "speed", "frequency", "torque"}
        # winding_temperature (degC, a number): only where the rig has a
        # winding thermometer; an additive key, absent otherwise.
        optional = {"winding_temperature"}
        if not keys <= set(msg) <= keys | optional:
            return f"keys {sorted(msg)}, want {sorted(keys)} and optionally {sorted(optional)}"
        if "winding_temperature" in msg and not is_number(msg["winding_temperature"]):
            return f"winding_temperature {msg['winding_temperature']!r} is not a number"
        if not is_int(msg["segment"]) or msg["segment"] < 0:
            return "segment is not a non-negative integer"
        for k in sorted(keys - {"segment", "torque"}):
            if not is_number(msg[k]):
                return f"{k} {msg[k]!r} is not a number"
        if msg["torque"] is not None and not is_number(msg["torque"]):
            return f"torque {msg['torque']!r} is not a number or null"
        return None
    if schema_name == "motorbench.SupplyLimit":
        keys = {"segment", "kind", "from", "to", "commanded_voltage",
                "measured_voltage", "current_limit", "peak_current"}
        if not keys <= set(msg):
            return f"keys {sorted(msg)}, want at least {sorted(keys)}"
        if not is_int(msg["segment"]) or msg["segment"] < 0:
            return "segment is not a non-negative integer"
        if msg["kind"] not in SUPPLY_LIMIT_KINDS:
            return f"kind {msg['kind']!r} is not one of {SUPPLY_LIMIT_KINDS}"
        for k in ("from", "to", "commanded_voltage", "measured_voltage", "peak_current"):
            if not is_number(msg[k]):
                return f"{k} {msg[k]!r} is not a number"
        if msg["current_limit"] is not None and not is_number(msg["current_limit"]):
            return f"current_limit {msg['current_limit']!r} is not a number or null"
        return None
    if schema_name == "motorbench.StandardTest":
        if msg.get("test") not in STANDARD_TESTS:
            return f"test {msg.get('test')!r} is not one of {STANDARD_TESTS}"
        if msg["test"] == "im_dc_resistance":
            keys = ("dc_voltage", "dc_current")
        else:
            keys = ("line_voltage", "line_current", "input_power", "frequency")
        if not set(keys) | {"segment", "winding_temperature"} <= set(msg):
            return f"keys {sorted(msg)}, want at least {sorted(keys)}, segment, winding_temperature"
        if not is_int(msg["segment"]) or msg["segment"] < 0:
            return "segment is not a non-negative integer"
        for k in keys:
            if not is_number(msg[k]):
                return f"{k} {msg[k]!r} is not a number"
        t = msg["winding_temperature"]
        if t is not None and not is_number(t):
            return f"winding_temperature {t!r} is not a number or null"
        return None
    if schema_name == "motorbench.Result":
        return None  # any JSON object
    return f"unknown schema {schema_name!r}"


def expected_schema(topic, version):
    if topic.startswith(SAMPLE_PREFIXES):
        return SAMPLE_SCHEMA
    if topic == "/bench/event" and version != "1":
        return "foxglove.Log"
    return BENCH_SCHEMAS.get(topic)


def check_metadata(reader, fail, out):
    """Checks the metadata; returns (schema_version, origin of log_time in ns)."""
    records = [m for m in reader.iter_metadata() if m.name == METADATA_NAME]
    if not records:
        fail.add(f"no {METADATA_NAME} metadata record: not a motorbench record")
        return None, 0
    if len(records) > 1:
        fail.add(f"{len(records)} {METADATA_NAME} metadata records, want 1")
    md = records[0].metadata
    for key in METADATA_KEYS:
        if key not in md:
            fail.add(f"{METADATA_NAME} metadata has no {key!r}")
    version = md.get("schema_version")
    if version not in VERSIONS:
        fail.add(f"schema_version is {version!r}, want one of {VERSIONS}")
    origin = 0
    if version == "2":
        text = md.get("start_time_ns", "")
        if not text.isdigit():
            fail.add(f"start_time_ns {text!r} is not a whole number of ns")
        else:
            origin = int(text)
            try:
                if rfc3339_ns(md.get("started_at", "")) != origin:
                    fail.add(f"started_at {md.get('started_at')!r} is not start_time_ns {origin}")
            except ValueError as e:
                fail.add(f"started_at: {e}")
    if "kind" in md and md["kind"] not in KINDS:
        fail.add(f"kind {md['kind']!r} is not one of {KINDS}")
    if "started_at" in md and not RFC3339.match(md["started_at"]):
        fail.add(f"started_at {md['started_at']!r} is not RFC 3339")
    if "nameplate" in md:
        try:
            plate = strict_json(md["nameplate"])
            if not isinstance(plate, dict):
                fail.add("nameplate is not a JSON object")
        except ValueError as e:
            fail.add(f"nameplate is not JSON: {e}")
    out.append(
        f"metadata: schema_version={md.get('schema_version')!r} kind={md.get('kind')!r} "
        f"motor_id={md.get('motor_id')!r} started_at={md.get('started_at')!r}"
    )
    return version, origin


def check_channels(summary, version, fail, out):
    """Checks every channel; returns {channel id: schema name} of good ones."""
    schema_of = {}
    for cid, ch in sorted(summary.channels.items()):
        where = f"channel {ch.topic}"
        want = expected_schema(ch.topic, version)
        if want is None:
            fail.add(f"{where}: topic is not in the contract")
            continue
        if ch.message_encoding != "json":
            fail.add(f"{where}: message_encoding {ch.message_encoding!r}, want 'json'")
        schema = summary.schemas.get(ch.schema_id)
        if schema is None:
            fail.add(f"{where}: no schema (schema_id {ch.schema_id})")
            continue
        if schema.encoding != "jsonschema":
            fail.add(f"{where}: schema encoding {schema.encoding!r}, want 'jsonschema'")
        if schema.name != want:
            fail.add(f"{where}: schema {schema.name!r}, want {want!r}")
        try:
            text = strict_json(schema.data)
            if not isinstance(text, dict):
                fail.add(f"{where}: schema data is not a JSON object")
        except ValueError as e:
            fail.add(f"{where}: schema data is not JSON: {e}")
        if want == SAMPLE_SCHEMA:
            md = ch.metadata
            missing = [k for k in ("unit", "quantity", "source") if k not in md]
            if missing:
                fail.add(f"{where}: metadata lacks {missing}")
            if "quantity" in md:
                prefix = "/sensor/" if ch.topic.startswith("/sensor/") else "/command/"
                if ch.topic != prefix + md["quantity"]:
                    fail.add(
                        f"{where}: quantity {md['quantity']!r} does not match the topic"
                    )
        schema_of[cid] = schema.name
    sample = sum(1 for s in schema_of.values() if s == SAMPLE_SCHEMA)
    out.append(f"channels: {len(summary.channels)} ({sample} sample channels)")
    return schema_of


class _Where:
    """`<topic> at log_time <t>`, formatted only when a problem is reported."""

    __slots__ = ("topic", "log_time")

    def __init__(self, topic, log_time):
        self.topic, self.log_time = topic, log_time

    def __format__(self, spec):
        return format(f"{self.topic} at log_time {self.log_time}", spec)


def check_messages(reader, summary, schema_of, origin, fail, out):
    counts = {ch.topic: 0 for ch in summary.channels.values()}
    per_channel = {cid: 0 for cid in summary.channels}
    open_segments = {}  # index -> (kind, log_time)
    closed = set()
    total = 0
    for _schema, channel, message in reader.iter_messages(log_time_order=False):
        total += 1
        topic = channel.topic
        counts[topic] = counts.get(topic, 0) + 1
        per_channel[channel.id] = per_channel.get(channel.id, 0) + 1
        where = _Where(topic, message.log_time)
        if message.log_time != message.publish_time:
            fail.add(f"{where}: publish_time {message.publish_time} != log_time")
        if message.log_time < origin:
            fail.add(f"{where}: before the test's start ({origin})")
        name = schema_of.get(channel.id)
        if name is None:
            continue  # the channel itself was reported
        try:
            msg = strict_json(message.data)
        except (ValueError, UnicodeDecodeError) as e:
            fail.add(f"{where}: payload is not JSON: {e}")
            continue
        problem = shape_problem(name, msg)
        if problem:
            fail.add(f"{where}: {problem}")
            continue
        if name == "foxglove.Log":
            ts = msg["timestamp"]
            if ts["sec"] * 1_000_000_000 + ts["nsec"] != message.log_time:
                fail.add(f"{where}: timestamp {ts} is not the log_time")
        if name == "motorbench.Segment":
            idx, kind = msg["index"], msg["kind"]
            if msg["phase"] == "start":
                if idx in open_segments or idx in closed:
                    fail.add(f"{where}: segment {idx} starts twice")
                else:
                    open_segments[idx] = (kind, message.log_time)
            else:
                if idx not in open_segments:
                    fail.add(f"{where}: segment {idx} ends without a start")
                    continue
                start_kind, start_t = open_segments.pop(idx)
                closed.add(idx)
                if kind != start_kind:
                    fail.add(f"{where}: segment {idx} ends as {kind!r}, started as {start_kind!r}")
                if message.log_time < start_t:
                    fail.add(f"{where}: segment {idx} ends before it starts")
    for idx in sorted(open_segments):
        fail.add(f"segment {idx} has a start but no end")

    stats = summary.statistics
    if stats is None:
        fail.add("the summary has no statistics record")
    else:
        if stats.message_count != total:
            fail.add(f"read {total} messages, the statistics say {stats.message_count}")
        for cid, n in sorted(per_channel.items()):
            want = stats.channel_message_counts.get(cid, 0)
            if want != n:
                fail.add(f"channel id {cid}: read {n} messages, the statistics say {want}")
    out.append(f"messages: {total}")
    out.append(f"segments: {len(closed)} complete")
    return counts


def check_chunks(summary, fail, out):
    chunks = summary.chunk_indexes
    if not chunks:
        fail.add("no chunk indexes in the summary")
    compressions = sorted({c.compression for c in chunks})
    for c in chunks:
        if c.compression != "zstd":
            fail.add(f"chunk at offset {c.chunk_start_offset}: compression {c.compression!r}, want 'zstd'")
            break
    out.append(f"chunks: {len(chunks)} ({', '.join(compressions) or 'none'})")


def parse_expectations(items, parser):
    expected = {}
    for item in items or []:
        topic, sep, count = item.rpartition("=")
        if not sep or not topic or not count.isdigit():
            parser.error(f"--expect-topic wants TOPIC=COUNT, got {item!r}")
        expected[topic] = int(count)
    return expected


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", help="the MCAP file to check")
    parser.add_argument(
        "--expect-topic",
        action="append",
        metavar="TOPIC=COUNT",
        help="require exactly COUNT messages on TOPIC (repeatable)",
    )
    args = parser.parse_args(argv)
    expected = parse_expectations(args.expect_topic, parser)

    fail = Failures()
    out = [f"file: {args.file}"]
    counts = {}
    version = None
    try:
        with open(args.file, "rb") as f:
            f.seek(0, 2)
            if f.tell() < 2 * len(MAGIC):
                raise ValueError("too short for an MCAP file")
            f.seek(-len(MAGIC), 2)
            if f.read() != MAGIC:
                raise ValueError(
                    "it does not end with the MCAP magic: truncated, or not finished"
                )
            f.seek(0)
            reader = make_reader(f)
            header = reader.get_header()
            if header.profile != "":
                fail.add(f"header profile {header.profile!r}, want ''")
            if not header.library.startswith("motorbench/"):
                fail.add(f"header library {header.library!r} does not start with 'motorbench/'")
            out.append(f"header: profile={header.profile!r} library={header.library!r}")
            summary = reader.get_summary()
            if summary is None:
                fail.add("no summary section (the file was not finished)")
            else:
                version, origin = check_metadata(reader, fail, out)
                schema_of = check_channels(summary, version, fail, out)
                check_chunks(summary, fail, out)
                counts = check_messages(reader, summary, schema_of, origin, fail, out)
    except Exception as e:  # a damaged or foreign file: report, do not trace back
        fail.add(f"cannot read the file: {type(e).__name__}: {e}")

    for topic, want in sorted(expected.items()):
        got = counts.get(topic, 0)
        if got != want:
            fail.add(f"topic {topic}: {got} messages, expected {want}")

    for line in out:
        print(line)
    if fail:
        for text in fail.items:
            print(f"FAIL: {text}", file=sys.stderr)
        if fail.dropped:
            print(f"FAIL: ... and {fail.dropped} more problems", file=sys.stderr)
        print(f"{args.file}: does not follow the motorbench data contract", file=sys.stderr)
        return 1
    print(f"ok: follows the motorbench data contract (schema_version {version})")
    print(json.dumps(dict(sorted(counts.items())), sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
