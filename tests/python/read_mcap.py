#!/usr/bin/env python3
"""Reads an MCAP file with the reference Python reader (PyPI `mcap`, plus `zstandard` for
zstd chunks) and prints what it found as JSON:

    {"topics": {topic: count}, "schemas": {topic: schema name},
     "metadata": {name: {key: value}}, "messages": total, "indexed": true,
     "decoded": {topic: count}, "first": {topic: {field: value}},
     "attachments": {name: {"media_type": type, "bytes": n, "text": utf-8 text or null}}}

Every message is read twice: through the summary and indexes (the seeking reader, as Foxglove
does) and front to back (the streaming reader); the counts must agree. Every message on a `json`
channel must parse as strict JSON (no NaN/Infinity); every message on a `protobuf` channel must
decode (PyPI `mcap-protobuf-support`) with nothing but the schema inside the file, and
`"decoded"` counts those per topic, with the first message of each as a dict in `"first"`.
Exits non-zero, with the reason on stderr, if anything fails.

Usage: read_mcap.py FILE.mcap
"""

import json
import sys
from collections import Counter


def _reject_constant(name):
    raise ValueError(f"non-finite number {name} in a JSON message")


def main(argv):
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    try:
        from mcap.reader import NonSeekingReader, make_reader
    except ImportError as e:
        print(f"read_mcap.py: the mcap package is missing ({e}); pip install mcap zstandard",
              file=sys.stderr)
        return 3
    try:
        from google.protobuf.json_format import MessageToDict
        from mcap_protobuf.decoder import DecoderFactory
    except ImportError:
        DecoderFactory = None
    path = argv[1]
    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None:
                raise ValueError("no summary section (file not finished?)")
            topics = Counter()
            decoded = Counter()
            first = {}
            schemas = {}
            protobuf = DecoderFactory() if DecoderFactory is not None else None
            for schema, channel, message in reader.iter_messages():
                topics[channel.topic] += 1
                if schema is not None:
                    schemas[channel.topic] = schema.name
                if channel.message_encoding == "json":
                    json.loads(message.data, parse_constant=_reject_constant)
                elif channel.message_encoding == "protobuf":
                    if protobuf is None:
                        raise ValueError("protobuf channels need mcap-protobuf-support")
                    decode = protobuf.decoder_for("protobuf", schema)
                    if decode is None:
                        raise ValueError(f"no protobuf decoder for {channel.topic}")
                    value = decode(message.data)
                    decoded[channel.topic] += 1
                    if channel.topic not in first:
                        first[channel.topic] = MessageToDict(
                            value, preserving_proto_field_name=True)
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
            attachments = {}
            for a in reader.iter_attachments():
                try:
                    text = bytes(a.data).decode("utf-8")
                except UnicodeDecodeError:
                    text = None
                attachments[a.name] = {"media_type": a.media_type, "bytes": len(a.data),
                                       "text": text}
            if summary.statistics is not None:
                if summary.statistics.message_count != sum(topics.values()):
                    raise ValueError("statistics message count disagrees with messages read")
        with open(path, "rb") as f:
            streamed = Counter()
            for _schema, channel, _message in NonSeekingReader(f).iter_messages():
                streamed[channel.topic] += 1
            if streamed != topics:
                raise ValueError(f"indexed and streamed reads disagree: {topics} vs {streamed}")
    except Exception as e:  # report any reader failure as a non-zero exit
        print(f"read_mcap.py: {path}: {type(e).__name__}: {e}", file=sys.stderr)
        return 1
    print(json.dumps({
        "topics": dict(sorted(topics.items())),
        "schemas": dict(sorted(schemas.items())),
        "metadata": metadata,
        "messages": sum(topics.values()),
        "indexed": True,
        "decoded": dict(sorted(decoded.items())),
        "first": first,
        "attachments": attachments,
    }, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
