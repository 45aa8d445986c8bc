#!/usr/bin/env python3
"""The README's picture: the live viewer on the default rig, taken headless.

    cargo build --release -p rig && python3 viz/screenshot.py [OUT.png] [SECONDS]

Starts a headless Rerun viewer on loopback (it renders with whatever Vulkan adapter there is;
on a machine without a GPU, Debian's mesa-vulkan-drivers gives the lavapipe rasterizer), runs
`rig up` streaming into it, and saves a screenshot while the rig runs. Needs
`pip install rerun-sdk==0.36.3`.
"""
import os
import pathlib
import signal
import subprocess
import sys
import time

import rerun.experimental as rrx

ROOT = pathlib.Path(__file__).resolve().parent.parent
OUT = pathlib.Path(sys.argv[1] if len(sys.argv) > 1 else ROOT / "viz" / "screenshot.png").resolve()
SECONDS = float(sys.argv[2]) if len(sys.argv) > 2 else 10.0
PORT = 9877
URL = f"rerun+http://127.0.0.1:{PORT}/proxy"

viewer = subprocess.Popen(
    ["rerun", "--headless", "--bind", "127.0.0.1", "--port", str(PORT),
     "--hide-welcome-screen", "--window-size", "1600x900", "--memory-limit", "1GB"],
    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
try:
    time.sleep(3.0)  # the viewer binds its port
    rig = subprocess.Popen(
        [str(pathlib.Path(os.environ.get("CARGO_TARGET_DIR", ROOT / "target")) / "release" / "rig"),
         "up", "--duration", str(SECONDS + 3),
         "--viewer", URL])
    time.sleep(SECONDS)
    client = rrx.ViewerClient.connect(URL)
    client.save_screenshot(str(OUT))
    rig.wait()
    print(f"screenshot saved to {OUT}")
finally:
    # `rerun` from pip is a launcher: stop its whole process group, the viewer with it.
    os.killpg(viewer.pid, signal.SIGTERM)
    viewer.wait()
