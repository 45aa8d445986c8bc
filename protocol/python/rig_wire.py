#!/usr/bin/env python3
"""Decoder for the VSA rig's wire format, version 1 (see ../WIRE.md). Standard library only.

    from rig_wire import decode
    msg = decode(payload_bytes)   # -> dict with "kind" and the fields, SI units

Run as a script with files of raw payloads (one message each) to print them as JSON lines.
"""
import json
import math
import struct
import sys

VERSION = 1
KINDS = {
    1: ("joint_sample", "<HHQQdddddd",
        ["joint", "flags", "seq", "t_acq_ns", "motor_rad", "deflection_rad"],
        ["pivot_m", "torque_nm", "motor_torque_nm", "stiffness_motor_rad"]),
    2: ("joint_command", "<HHQQdddB",
        ["joint", "flags", "seq", "t_ns"],
        ["motor_goal_rad", "pivot_goal_m", "stiffness_motor_goal_rad"]),
    8: ("sim_truth", "<HQQdddd",
        ["joint", "seq", "t_acq_ns", "deflection_rad", "torque_nm", "link_rad", "stiffness_nm_per_rad"],
        []),
    4: ("joint_estimate", "<HHQQddddddd",
        ["joint", "flags", "seq", "t_acq_ns", "torque_nm"],
        ["stiffness_nm_per_rad", "inertia_kg_m2", "inertia_var", "damping_nms_per_rad", "damping_var", "residual_nm"]),
}
STATES = ["ok", "rejected", "safe_hold", "fault", "stopped", "stale"]


class WireError(ValueError):
    pass


def _text(buf, off):
    (n,) = struct.unpack_from("<H", buf, off)
    raw = bytes(buf[off + 2: off + 2 + n])
    if len(raw) != n:
        raise WireError("text truncated")
    return raw.decode("utf-8"), off + 2 + n


def decode(buf):
    """Decodes one payload; raises WireError for anything malformed."""
    try:
        return _decode(buf)
    except (struct.error, UnicodeDecodeError, IndexError) as e:
        raise WireError(f"malformed body: {e}") from e


def _decode(buf):
    if len(buf) < 8:
        raise WireError("shorter than the header")
    magic, version, kind, n = struct.unpack_from("<2sBBI", buf)
    if magic != b"VR" or version != VERSION:
        raise WireError(f"not a version {VERSION} rig message")
    body = memoryview(buf)[8:]
    if len(body) != n:
        raise WireError("body length mismatch")
    if kind in KINDS:
        name, out = _fixed(kind, body)
    elif kind == 9:
        (cnt,) = struct.unpack_from("<H", body)
        size = struct.calcsize(KINDS[1][1])
        if not 1 <= cnt <= 1024 or len(body) != 2 + cnt * size:
            raise WireError("wrong body size")
        samples = [_fixed(1, body[2 + i * size: 2 + (i + 1) * size])[1] for i in range(cnt)]
        if len({x["joint"] for x in samples}) != cnt:
            raise WireError("a joint appears twice")
        for x in samples:
            x["kind"] = "joint_sample"
        out = dict(samples=samples)
        name = "board_sample"
    elif kind == 3:
        joint, state, seq, t_ns = struct.unpack_from("<HBQQ", body)
        text, end = _text(body, struct.calcsize("<HBQQ"))
        out = dict(joint=joint, state=STATES[state], seq=seq, t_ns=t_ns, text=text)
        name = "joint_status"
    elif kind == 5:
        v = struct.unpack("<HIQQdddddddd", body)
        flags = v[0]
        out = dict(stale_mask=v[1], seq=v[2], t_ns=v[3], x_m=v[4], y_m=v[5], phi_rad=v[6],
                   force_n=[v[7], v[8]] if flags & 1 else None,
                   stiffness_n_per_m=dict(xx=v[9], xy=v[10], yy=v[11]) if flags & 2 else None)
        name = "ee_estimate"
    elif kind == 6:
        v = struct.unpack("<QddBddd", body)
        target = dict(percent=v[4]) if v[3] == 1 else dict(xx=v[4], xy=v[5], yy=v[6])
        out = dict(id=v[0], x_m=v[1], y_m=v[2], target=target)
        name = "allocation_request"
    elif kind == 7:
        head = "<QBdddddddB"
        v = struct.unpack_from(head, body)
        off = struct.calcsize(head)
        cnt = v[-1]
        ks = list(struct.unpack_from(f"<{cnt}d", body, off))
        ds = list(struct.unpack_from(f"<{cnt}d", body, off + 8 * cnt))
        error, _ = _text(body, off + 16 * cnt)
        out = dict(id=v[0], feasible=bool(v[1]), residual=v[2],
                   target=dict(xx=v[3], xy=v[4], yy=v[5]), achieved=dict(xx=v[6], xy=v[7], yy=v[8]),
                   k_joint_nm_per_rad=ks, pivot_m=ds, error=error)
        name = "allocation_result"
    else:
        raise WireError(f"unknown kind {kind}")
    _check_finite(out)
    out["kind"] = name
    return out


def _fixed(kind, body):
    """A body of fixed size whose optional values follow their flag bits: (name, fields)."""
    name, fmt, fixed, optional = KINDS[kind]
    if len(body) != struct.calcsize(fmt):
        raise WireError("wrong body size")
    vals = struct.unpack(fmt, body)
    out = dict(zip(fixed, vals))
    slots = vals[len(fixed):len(fixed) + len(optional)]
    for i, (key, v) in enumerate(zip(optional, slots)):
        out[key] = v if out["flags"] & (1 << i) else None
    if kind == 2:
        out["torque_enable"] = bool(vals[-1])
    out.pop("flags", None)
    _check_finite(out)
    return name, out


def _check_finite(out):
    for key, val in out.items():
        if isinstance(val, float) and not math.isfinite(val):
            raise WireError(f"{key} is not finite")


if __name__ == "__main__":
    for path in sys.argv[1:]:
        with open(path, "rb") as f:
            print(json.dumps(decode(f.read()), sort_keys=True))
