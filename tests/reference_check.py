"""Comparison of the reference preset's outputs with a record of per-frame expected values.

Shared by the golden test (the published implementation's outputs) and the repository's own
regression fixture, which has the same format.
"""

from __future__ import annotations

import math

import numpy as np

from asnn import ASNN

# The published implementation's orientation k is our orientation (4 - k) mod 8 (see
# asnn.retina.gabor_pair); its motion vectors have the opposite x component.
PUBLISHED_ORIENTATION = [(4 - k) % 8 for k in range(8)]


def close(a: float, b: float) -> bool:
    """Equal to float64 precision (SPEC.md section 3), with room for another machine's order of
    summation: the reference preset differs from the golden outputs by at most 1e-14
    (relative), the float32 reference32 by up to 5e-7."""
    return abs(a - b) <= max(1e-12, 1e-10 * abs(b))


def run_reference(frames: np.ndarray) -> list:
    model = ASNN("reference", record_maps=True)
    return [model.step(f) for f in frames]


def mismatches(responses: list, expected: list[dict]) -> list[str]:
    """Every field of every frame that differs beyond the golden tolerance."""
    problems = []
    for response, want in zip(responses, expected):
        i = want["frame"]
        if "u" not in want:  # frame 0: no output
            continue
        maps = response.maps
        got = {"u": response.u, "out": response.out, "sum_G": float(maps.G.sum()),
               "sum_E_max": float(maps.V.sum())}
        for key, value in got.items():
            if not close(value, want[key]):
                problems.append(f"frame {i} {key}: {value!r} != {want[key]!r}")
        if response.spike_rate != want["spike_rate"] or response.collision != want["collision"]:
            problems.append(f"frame {i} spike_rate/collision: {response.spike_rate}, "
                            f"{response.collision} != {want['spike_rate']}, {want['collision']}")
        for key, mask in (("count_M_a", maps.M_a), ("count_M_d", maps.M_d)):
            if int(mask.sum()) != want[key]:
                problems.append(f"frame {i} {key}: {int(mask.sum())} != {want[key]}")
        sums = maps.R.sum(axis=(1, 2))[PUBLISHED_ORIENTATION]
        for k, (a, b) in enumerate(zip(sums, want["E_sum_by_orientation"])):
            if not close(float(a), b):
                problems.append(f"frame {i} E_sum[{k}]: {a!r} != {b!r}")
        if len(response.targets) != len(want["targets"]):
            problems.append(f"frame {i} targets: {len(response.targets)} != {len(want['targets'])}")
            continue
        for t, w in zip(response.targets, want["targets"]):
            dx = -t.energy * math.cos(t.direction)
            dy = t.energy * math.sin(t.direction)
            if not all(close(a, b) for a, b in ((t.x, w["x"]), (t.y, w["y"]), (dx, w["dx"]),
                                                (dy, w["dy"]))):
                problems.append(f"frame {i} target {t} != {w}")
    return problems


def record(responses: list) -> list[dict]:
    """Expected values in the golden format, for writing a regression fixture."""
    rows = [{"frame": 0}]
    for r in responses[1:]:
        m = r.maps
        rows.append({
            "frame": r.index, "u": r.u, "out": r.out, "spike_rate": r.spike_rate,
            "collision": r.collision, "sum_G": float(m.G.sum()), "sum_E_max": float(m.V.sum()),
            "count_M_a": int(m.M_a.sum()), "count_M_d": int(m.M_d.sum()),
            "E_sum_by_orientation": [float(x) for x in m.R.sum(axis=(1, 2))[PUBLISHED_ORIENTATION]],
            "targets": [{"x": t.x, "y": t.y, "dx": -t.energy * math.cos(t.direction),
                         "dy": t.energy * math.sin(t.direction)} for t in r.targets]})
    return rows
