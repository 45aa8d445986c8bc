"""Reads `rig identify` JSON reports (paths on stdin) and prints the springs table."""
import json
import os
import re
import sys

SHORT = {
    "hysteresis": lambda p: f"hysteresis (±{p['loop_half_height_nm']:.2f} N·m, {p['operators']:.0f} stops)",
    "coulomb_friction": lambda p: f"coulomb_friction ({p['friction_nm']:.2f} N·m"
    + (", held at rest" if p.get("held_at_rest") == 1 else "")
    + (f", built up over {p['builds_over_rad_per_s'] * 1e3:.3g} mrad/s" if p.get("builds_over_rad_per_s", 0) > 0 else "")
    + ")",
    "viscous_friction": lambda p: f"viscous_friction ({p['damping_nms_per_rad']:.3g} N·m·s/rad)",
    "backlash": lambda p: f"backlash ({p['width_rad'] * 1e3:.2f} mrad)",
    "hard_stop": lambda p: "hard_stop (from "
    + " and ".join(
        f"{p[k] * 1e3:+.2f} mrad" for k in ("onset_rad", "onset_negative_rad") if k in p
    )
    + ")",
    "sensor_delay": lambda p: f"sensor_delay ({p['delay_s'] * 1e3:.1f} ms)",
    "offset": lambda p: f"offset on the {p.get('on', 'torque')} ("
    + ", ".join(
        ([f"{p['bias_nm']:+.2f} N·m"] if "bias_nm" in p else [])
        + ([f"{p['bias_rad'] * 1e3:+.2f} mrad"] if "bias_rad" in p else [])
        + ([f"jump {p['jump_rad'] * 1e3:+.2f} mrad at {p['jump_at_s']:.1f} s"] if "jump_rad" in p else [])
        + ([f"jump {p['jump_nm']:+.2f} N·m at {p['jump_at_s']:.1f} s"] if "jump_nm" in p else [])
    )
    + ")",
    "stiffness_drift": lambda p: f"stiffness_drift ({100 * p['stiffness_step']:+.1f} % at {p['step_at_s']:.1f} s)"
    if "stiffness_step" in p
    else f"stiffness_drift ({100 * p['stiffness_change_over_run']:+.1f} % over the run)",
    "periodic_ripple": lambda p: f"periodic_ripple ({p['amplitude_nm']:.2f} N·m per {p['period_rad'] * 1e3:.2f} mrad)",
    "geometric_stiffness": lambda p: "geometric_stiffness",
    "gravity": lambda p: "gravity",
}

rows = []
for line in sys.stdin:
    path = line.strip()
    if not path:
        continue
    r = json.load(open(path))
    m = re.match(r"spring(\d+)-([\d.]+)nm", os.path.basename(path))
    spring, amp = int(m.group(1)), float(m.group(2))
    fit = os.path.basename(r["data"][0]).split("-")[3]
    held = os.path.basename(r["holdout"]["files"][0]).split("-")[3]
    k = r["base"]["before"]["stiffness_nm_per_rad"]
    effects = "; ".join(
        # The held-out RMSE's change: − where it fell, + where it rose (a tare that hurt).
        SHORT[e["name"]](e["params"])
        + (f" −{g:.3f}" if (g := e["gain_rmse"]) >= 0 else f" +{-g:.3f}")
        for e in r["effects"]
    ) or "none"
    bias = max((abs(b["mean_residual_nm"]) for b in r["bias"]), default=0.0)
    steps = sum(int(n.split()[1]) for n in r["notes"] if n.startswith("steps:"))
    lag = next((e["params"]["delay_s"] for e in r["effects"] if e["name"] == "sensor_delay"), None)
    tare = "; ".join(
        f"{t['torque_zero']:+.3f} N·m, {t['deflection_zero'] * 1e3:+.2f} mrad"
        + (" (its own rest: the zero moved)" if t.get("frame_at_rest") else "")
        + (f", state {t['loop_state']:+.2f}" if t.get("loop_state") is not None else "")
        + (f" (its rest's {t['zero_not_taken_nm']:+.3f} N·m not taken)" if t.get("zero_not_taken_nm") is not None else "")
        for t in r["tare"]
    ) if isinstance(r["tare"], list) and r["tare"] else "none"
    rows.append((spring, amp, fit, held, k, r["before"]["rmse"], r["tared"]["rmse"], r["after"]["rmse"], effects, bias, steps, tare))

print("| spring | T [N·m] | fit / held-out test | k linear [N·m/rad] | RMSE before [N·m] | tared [N·m] | after [N·m] | before/after | effects added (held-out RMSE gain, N·m) | held-out bias [N·m] | torque steps | tare (fit file; held-out file) |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
ratios = []
for s, a, f, h, k, b, t, af, e, bias, steps, tare in sorted(rows):
    ratios.append(b / af)
    print(f"| {s} | {a:g} | {f} / {h} | {k:.4g} | {b:.3f} | {t:.3f} | {af:.3f} | {b / af:.2f} | {e} | {bias:.3f} | {steps} | {tare} |")
ratios.sort()
n = len(ratios)
median = ratios[n // 2] if n % 2 else 0.5 * (ratios[n // 2 - 1] + ratios[n // 2])
print()
print(f"Median before/after over {n} pairs: {median:.2f}; smallest {ratios[0]:.2f}.")
