#!/usr/bin/env python3
"""Reference-reader interop check for atmo-io's MCAP logs.

Opens every log the Rust tests left in a folder (default
target/tmp/atmo-io-interop) with the reference readers (`mcap` and
`mcap-ros2-support`), decodes every message of every channel from the
`ros2msg` schema in the file, and compares each field with
`<log>.expected.json` (what the Rust test sent; JSON null stands for a
non-finite float). Also reads the truncated log of a killed writer with the
non-seeking reader. Exits non-zero on the first mismatch.
"""

import json
import math
import struct
import sys
from pathlib import Path

from mcap.reader import NonSeekingReader, make_reader
from mcap_ros2.decoder import DecoderFactory

# float32 fields: the JSON holds the shortest decimal of the f32 value.
F32_FIELDS = {
    "px4_msgs/msg/VehicleOdometry": {
        "position", "q", "velocity", "angular_velocity",
        "position_variance", "orientation_variance", "velocity_variance",
    },
    "px4_msgs/msg/ActuatorMotors": {"control"},
}


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def compare(path, actual, expected, f32_fields, where, top=True):
    if expected is None:
        if not (isinstance(actual, float) and not math.isfinite(actual)):
            raise AssertionError(f"{where}: expected a non-finite float, got {actual!r}")
        return
    if isinstance(expected, dict):
        for key, value in expected.items():
            if not hasattr(actual, key):
                raise AssertionError(f"{where}: decoded message has no field `{key}`")
            compare(path, getattr(actual, key), value, f32_fields if top else set(),
                    f"{where}.{key}", top=False)
        return
    if isinstance(expected, list):
        actual = list(actual)
        if len(actual) != len(expected):
            raise AssertionError(f"{where}: length {len(actual)}, expected {len(expected)}")
        field = where.rsplit(".", 1)[-1]
        for i, (a, e) in enumerate(zip(actual, expected)):
            if field in f32_fields and e is not None:
                e = f32(e)
            compare(path, a, e, set(), f"{where}[{i}]", top=False)
        return
    if isinstance(expected, bool):
        if bool(actual) != expected or not isinstance(actual, (bool, int)):
            raise AssertionError(f"{where}: {actual!r} != {expected!r}")
        return
    if isinstance(expected, float) and isinstance(actual, float) and math.isnan(actual):
        raise AssertionError(f"{where}: NaN, expected {expected!r}")
    if actual != expected:
        raise AssertionError(f"{where}: {actual!r} != {expected!r}")


def check_finished(log):
    expected = json.loads(Path(str(log) + ".expected.json").read_text())
    seen = 0
    topics = set()
    with open(log, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == "ros2", f"{log}: profile {header.profile!r}"
        summary = reader.get_summary()
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert channel.message_encoding == "cdr", channel
            assert schema.encoding == "ros2msg", schema
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            if seen >= len(expected):
                raise AssertionError(f"{log}: more messages than expected ({len(expected)})")
            want = expected[seen]
            where = f"{log.name}#{seen} {channel.topic}"
            assert channel.topic == want["topic"], f"{where}: topic, expected {want['topic']}"
            assert schema.name == want["schema"], f"{where}: schema {schema.name}"
            assert message.sequence == want["sequence"], f"{where}: sequence"
            assert message.log_time == want["log_time"], f"{where}: log_time"
            assert message.publish_time == want["publish_time"], f"{where}: publish_time"
            compare(log, decoded, want["message"], F32_FIELDS.get(schema.name, set()), where)
            topics.add(channel.topic)
            seen += 1
    if seen != len(expected):
        raise AssertionError(f"{log}: decoded {seen} messages, expected {len(expected)}")
    return seen, topics


def check_partial(log, recovered_expected):
    """A killed writer's file: no footer; the non-seeking reader in file order."""
    expected = json.loads(Path(recovered_expected).read_text())
    seen = 0
    factory = DecoderFactory()
    decoders = {}
    with open(log, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True)
        try:
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                decoder = decoders.get(schema.id) or factory.decoder_for(channel.message_encoding, schema)
                decoders[schema.id] = decoder
                want = expected[seen]
                where = f"{log.name}#{seen} {channel.topic}"
                assert channel.topic == want["topic"], where
                compare(log, decoder(message.data), want["message"],
                        F32_FIELDS.get(schema.name, set()), where)
                seen += 1
        except AssertionError:
            raise
        except Exception as e:  # the truncated end of the file
            print(f"  {log.name}: reader stopped at the truncation: {type(e).__name__}: {e}")
    if seen == 0:
        raise AssertionError(f"{log}: no message readable")
    return seen


def self_test(log):
    """The comparison must notice a changed value, a changed length, a NaN."""
    expected = json.loads(Path(str(log) + ".expected.json").read_text())
    with open(log, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            want = expected[0]["message"]
            break
    compare(log, decoded, want, set(), "self-test")
    for mutate in ("value", "length"):
        bad = json.loads(json.dumps(want))
        target = bad
        while True:  # first list or float in the message
            key = next(k for k, v in target.items() if isinstance(v, (dict, list, float)))
            if isinstance(target[key], dict):
                target = target[key]
                continue
            if isinstance(target[key], list):
                if mutate == "length":
                    target[key].append(0.0)
                else:
                    target[key][0] = (target[key][0] or 0.0) + 1e-9
            else:
                target[key] += 1e-9
            break
        try:
            compare(log, decoded, bad, set(), "self-test")
        except AssertionError:
            continue
        raise RuntimeError(f"self-test: a changed {mutate} was not noticed")


def main():
    folder = Path(sys.argv[1] if len(sys.argv) > 1 else "target/tmp/atmo-io-interop")
    logs = sorted(folder.glob("*.mcap"))
    if not logs:
        print(f"check_mcap: no logs in {folder}: run `cargo test -p atmo-io` first", file=sys.stderr)
        return 1
    self_test(logs[0])
    passed = failed = 0
    for log in logs:
        try:
            count, topics = check_finished(log)
            print(f"  {log.name}: {count} messages on {len(topics)} topics decoded and equal")
            passed += 1
        except Exception as e:
            print(f"FAILED {log}: {type(e).__name__}: {e}", file=sys.stderr)
            failed += 1
    for partial in sorted(folder.glob("*.mcap.partial")):
        recovered = partial.with_name(partial.name.replace(".mcap.partial", "_recovered.mcap.expected.json"))
        try:
            count = check_partial(partial, recovered)
            print(f"  {partial.name}: {count} messages of the truncated log decoded and equal")
            passed += 1
        except Exception as e:
            print(f"FAILED {partial}: {type(e).__name__}: {e}", file=sys.stderr)
            failed += 1
    print(f"check_mcap: {passed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
