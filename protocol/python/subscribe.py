#!/usr/bin/env python3
"""Subscribe to a running rig from Python and print decoded messages as JSON lines.

    pip install eclipse-zenoh==1.10.2
    python3 protocol/python/subscribe.py tcp/127.0.0.1:7447 'rig/parallel/joint/j1/sample' 5

Connects to the given endpoint only (multicast scouting off), decodes each payload with
rig_wire.decode (standard library only) and exits after COUNT messages, or with status 2
after TIMEOUT seconds (default 10) without enough of them.
"""
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import zenoh  # noqa: E402
from rig_wire import decode  # noqa: E402


def main():
    if len(sys.argv) < 3:
        print(__doc__, file=sys.stderr)
        return 1
    endpoint, key = sys.argv[1], sys.argv[2]
    count = int(sys.argv[3]) if len(sys.argv) > 3 else 1
    timeout = float(sys.argv[4]) if len(sys.argv) > 4 else 10.0
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("listen/endpoints", '["tcp/127.0.0.1:0"]')
    conf.insert_json5("scouting/multicast/enabled", "false")
    got = 0
    deadline = time.monotonic() + timeout
    with zenoh.open(conf) as session:
        sub = session.declare_subscriber(key)
        while got < count and time.monotonic() < deadline:
            sample = sub.try_recv()
            if sample is None:
                time.sleep(0.005)
                continue
            msg = decode(sample.payload.to_bytes())
            msg["key"] = str(sample.key_expr)
            print(json.dumps(msg, sort_keys=True), flush=True)
            got += 1
    return 0 if got >= count else 2


if __name__ == "__main__":
    sys.exit(main())
