#!/usr/bin/env python3
"""Reproduces EVALUATION.md "Against the fidelity targets", the hinge-side bound.

Question: are the generated hinges far from the real ones because they sit on the wrong edge
of the right door (a side a rule could pick, e.g. opposite the handle), or because the door
itself is elsewhere? For every GT revolute joint of an `eval real` run, this recomputes the
pivot error of real-scans.md §3 for the matched generated joint (the generated revolute joint
with the smallest axis angle; ties go to the nearest line) and for the same joint mirrored
onto the opposite side of its child's box (the hinge point reflected through the box centre,
across the axis). An oracle that always picked the better side bounds what any side rule
could gain.

  python3 scripts/eval/pivot-sides.py RUN [DATA]

RUN is an `eval real` output directory (real.json, jobs/<scan>/<row>/object.json); DATA the
benchmark set (default: real). Standard library only.
"""
import json
import math
import os
import sys

TOLERANCE = 0.05


def sub(a, b):
    return [x - y for x, y in zip(a, b)]


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def unit(a):
    n = math.sqrt(dot(a, a))
    return [x / n for x in a]


def line_distance(p, origin, axis):
    a, d = unit(axis), sub(p, origin)
    t = dot(d, a)
    return math.sqrt(max(dot(d, d) - t * t, 0.0))


def angle(a, b):
    return math.degrees(math.acos(min(1.0, abs(dot(unit(a), unit(b))))))


def diagonal(obj):
    lo = [min(p["center"][k] - p["half_extents"][k] for p in obj["parts"]) for k in range(3)]
    hi = [max(p["center"][k] + p["half_extents"][k] for p in obj["parts"]) for k in range(3)]
    return math.dist(lo, hi)


def mirrored(joint, parts):
    """The joint's origin reflected through its child's box centre, across the axis."""
    c, o, a = parts[joint["child"]]["center"], joint["origin"], unit(joint["axis"])
    d = sub(o, c)
    t = dot(d, a)
    perp = [x - t * y for x, y in zip(d, a)]
    return [x - 2 * y for x, y in zip(o, perp)]


def main():
    run = sys.argv[1]
    data = sys.argv[2] if len(sys.argv) > 2 else "real"
    report = json.load(open(f"{run}/real.json"))
    hinges = as_is = best_side = 0
    for scan in report["scans"]:
        gt = json.load(open(f"{data}/dataset/objects/{scan['object']}/object.json"))
        gt_parts = {p["name"]: p for p in gt["parts"]}
        diag = diagonal(gt)
        for job in scan["jobs"]:
            path = f"{run}/jobs/{scan['scan']}/{job['row']}/object.json"
            if not os.path.exists(path):
                continue
            out = json.load(open(path))
            parts = {p["name"]: p for p in out["parts"]}
            for j in gt["joints"]:
                if j["type"] != "revolute":
                    continue
                hinges += 1
                a = unit(j["axis"])
                c, o = gt_parts[j["child"]]["center"], j["origin"]
                hinge = [x + dot(sub(c, o), a) * y for x, y in zip(o, a)]
                cands = [(angle(j["axis"], g["axis"]), g) for g in out["joints"]
                         if g["type"] == "revolute"]
                if not cands:
                    continue
                low = min(x[0] for x in cands)
                tied = [g for d, g in cands if d <= low + 1e-9]
                here = min(line_distance(hinge, g["origin"], g["axis"]) for g in tied) / diag
                there = min(line_distance(hinge, mirrored(g, parts), g["axis"])
                            for g in tied) / diag
                as_is += here <= TOLERANCE
                best_side += min(here, there) <= TOLERANCE
                print(f"{scan['scan']} {job['row']} {j['child']}: axis {low:.1f}°, "
                      f"pivot {here:.3f}, other side {there:.3f}")
    print(f"GT hinges {hinges}: pivot ≤ {TOLERANCE} as generated {as_is}, "
          f"with the better side {best_side}")


if __name__ == "__main__":
    main()
