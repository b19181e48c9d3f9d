#!/usr/bin/env python3
"""Reproduces EVALUATION.md "Choosing the front by the guided fit".

Question: can the guided fit choose among the four axis-aligned yaw hypotheses of a scan
(issue: "choose ... by the guided fit otherwise: sample the best hypotheses and rank them")?
Each benchmark scan, given in physnap's canonical frame, is turned about its box centre by
0°, 90°, 180° and 270° (camera turned with it; 0° is the truth). Every turn is generated as if
it were canonical (`physnap generate`, seed 0, one sample, the scan's category), once with the
camera and once without, and the best sample's ranking score (ranking.json: D_pc + free space
+ attachment + O_mesh + contact depth) says which turn the fit prefers.

  python3 scripts/eval/frame-fit.py [--data real] [--out out/frame-fit] [--views 1]
                                   [--modes camera,nocamera]

With the camera, only turns whose front faces the camera within 75° compete (the frame
estimate's own rule: a front at 90° or more from the camera is not a hypothesis); without it,
all four. Reports, per mode, how often the lowest score, the lowest D_pc alone and (with the
camera) the turn facing the camera most squarely pick the truth. Finished jobs are skipped on
a rerun. PHYSNAP_BIN names the binary (default: physnap on PATH). Standard library only.
"""
import argparse
import json
import math
import os
import struct
import subprocess
import sys

TURNS = (0, 90, 180, 270)
# cos 75°: a turn whose front is farther than this from the camera direction is not a hypothesis.
VIABLE_COS = math.cos(math.radians(75.0))


def read_ply(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    n = int(next(l for l in header.split("\n") if l.startswith("element vertex")).split()[-1])
    if "binary_little_endian" not in header:
        sys.exit(f"{path}: only binary little-endian x, y, z float PLYs are read here")
    return [struct.unpack_from("<3f", data, end + 12 * i) for i in range(n)]


def write_ply(path, pts):
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(pts)}\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    with open(path, "wb") as f:
        f.write(head.encode())
        for p in pts:
            f.write(struct.pack("<3f", *p))


def turn(pts, eye, deg):
    """Turn about the footprint's box centre by `deg` about +Z, recentre the footprint."""
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    cx, cy = (min(xs) + max(xs)) / 2, (min(ys) + max(ys)) / 2
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))

    def rot(x, y):
        return c * (x - cx) - s * (y - cy), s * (x - cx) + c * (y - cy)

    q = [(*rot(p[0], p[1]), p[2]) for p in pts]
    qx, qy = [p[0] for p in q], [p[1] for p in q]
    sx, sy = (min(qx) + max(qx)) / 2, (min(qy) + max(qy)) / 2
    q = [(p[0] - sx, p[1] - sy, p[2]) for p in q]
    ex, ey = rot(eye[0], eye[1])
    e = (ex - sx, ey - sy, eye[2])
    h = math.hypot(e[0], e[1])
    # The front faces −X: how squarely it faces the camera's horizontal direction.
    return q, e, (-e[0] / h if h > 0 else 0.0)


def best_sample(ranking):
    r = json.load(open(ranking))
    b = next(x for x in r["samples"] if x["best"])
    return b["score"], b["terms"]["d_pc_per_scan_diagonal"]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default="real")
    ap.add_argument("--out", default="out/frame-fit")
    ap.add_argument("--views", type=int, default=1, help="views per object (0: all)")
    ap.add_argument("--weights", default="weights")
    ap.add_argument("--modes", default="camera,nocamera",
                    help="comma-separated: camera (generate with the scan's camera), nocamera")
    a = ap.parse_args()
    bin_ = os.environ.get("PHYSNAP_BIN", "physnap")
    objects = {o["id"]: o for o in json.load(open(f"{a.data}/dataset/dataset.json"))["objects"]}
    scans = sorted(
        f[: -len(".camera.json")]
        for f in os.listdir(f"{a.data}/scans")
        if f.endswith(".camera.json")
    )
    scans = [s for s in scans if a.views == 0 or int(s.rsplit("_", 1)[1]) < a.views]
    os.makedirs(a.out, exist_ok=True)
    results = {"camera": {}, "no camera": {}}
    for n, scan in enumerate(scans):
        obj = objects[scan.rsplit("_", 1)[0]]
        eye = json.load(open(f"{a.data}/scans/{scan}.camera.json"))["eye"]
        pts = read_ply(f"{a.data}/scans/{scan}.ply")
        for deg in TURNS:
            q, e, cos = turn(pts, eye, deg)
            ply = f"{a.out}/{scan}_{deg}.ply"
            if not os.path.exists(ply):
                write_ply(ply, q)
            for mode, cam in (("camera", e), ("no camera", None)):
                if mode.replace(" ", "") not in a.modes.split(","):
                    continue
                if cam is not None and cos < VIABLE_COS:
                    continue
                job = f"{a.out}/{'cam' if cam else 'nocam'}/{scan}_{deg}"
                if not os.path.exists(f"{job}/ranking.json"):
                    cmd = [bin_, "generate", "--weights", a.weights, "--points", ply,
                           "--category", obj["category"], "--seed", "0", "--out", job]
                    if cam is not None:
                        cmd.append("--camera=" + ",".join(f"{v:.4f}" for v in cam))
                    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL)
                score, dpc = best_sample(f"{job}/ranking.json")
                results[mode].setdefault(scan, {})[deg] = (score, dpc, cos)
        print(f"{n + 1}/{len(scans)} {scan}", file=sys.stderr)
    summary = {}
    for mode, per_scan in results.items():
        if not per_scan:
            continue
        contested = {s: h for s, h in per_scan.items() if len(h) >= 2}
        pick = lambda key: sum(min(h, key=lambda d: key(h[d])) == 0 for h in contested.values())
        row = {
            "scans": len(per_scan),
            "contested": len(contested),
            "score_right": pick(lambda v: v[0]),
            "d_pc_right": pick(lambda v: v[1]),
        }
        if mode == "camera":
            row["camera_right"] = pick(lambda v: -v[2])
        summary[mode] = row
        print(mode, json.dumps(row))
    json.dump({"summary": summary, "per_scan": results}, open(f"{a.out}/frame-fit.json", "w"),
              indent=1)


if __name__ == "__main__":
    main()
