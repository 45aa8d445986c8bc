#!/usr/bin/env python3
"""Read a rig recording (MCAP) with the `mcap` package and nothing of the rig's.

Each channel says how to read it. A channel of message encoding `json` carries one rig
message per record, described by its channel's schema (encoding `jsonschema`, name
`rig.<Kind>`, a self-contained draft-7 JSON Schema): the message is `json.loads` of the record,
and it is checked against that schema. A channel of encoding `rig-wire/1` (schema
`rig.Unreadable`) holds payloads that arrived but were not valid rig messages, kept as bytes.

Prints one JSON object per message, in the file's order:
  {"topic", "schema", "sequence", "log_time_ns", "message"}   (json channels)
  {"topic", "schema", "sequence", "log_time_ns", "wire_hex"}  (rig-wire/1 channels)

Usage: python3 read_recording.py run.mcap
Needs: pip install mcap jsonschema   (`cargo xtask test` puts both in .venv/)
"""

import json
import sys

import jsonschema
from mcap.reader import make_reader


def main(path):
    validators = {}
    with open(path, "rb") as f:
        for schema, channel, record in make_reader(f).iter_messages(log_time_order=False):
            out = {
                "topic": channel.topic,
                "schema": schema.name if schema else "",
                "sequence": record.sequence,
                "log_time_ns": record.log_time,
            }
            if channel.message_encoding == "json":
                if schema is None or schema.encoding != "jsonschema":
                    sys.exit(f"{channel.topic}: a json channel without a jsonschema schema")
                v = validators.get(schema.id)
                if v is None:
                    s = json.loads(schema.data)
                    jsonschema.Draft7Validator.check_schema(s)
                    v = validators[schema.id] = jsonschema.Draft7Validator(s)
                message = json.loads(record.data)
                errors = sorted(v.iter_errors(message), key=str)
                if errors:
                    sys.exit(
                        f"{channel.topic} message {record.sequence} does not match "
                        f"{schema.name}: {errors[0].message}"
                    )
                out["message"] = message
            elif channel.message_encoding == "rig-wire/1":
                out["wire_hex"] = record.data.hex()
            else:
                sys.exit(f"{channel.topic}: unknown message encoding {channel.message_encoding!r}")
            print(json.dumps(out))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
