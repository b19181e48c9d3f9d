#!/usr/bin/env python3
"""sim_check.py: the sim-clean check of docs real-scans.md §3, in MuJoCo.

Why it exists: "the URDF loads in a physics engine and moves" is one of the metrics physnap
reports on real scans (`physnap eval real`), and only an engine can say it; the CI test
tests/sim_engine.rs also holds physnap's native check (`physnap check-sim`) to MuJoCo's verdicts
with it. For every URDF or MJCF file given (`robot.urdf` / `model.xml`, each with its meshes/
folder, as `physnap export` / `generate` write them) this prints one JSON document on stdout:

    {"format": "physnap.sim_check/v1", "mujoco": "4.0.0", "depth": 0.005, "states": 5,
     "results": [{"urdf": PATH, "compiled": bool, "error": str|null, "bodies": n,
                  "joints": n, "rest_depth": m, "sweep_depth": m, "worst": {...}|null,
                  "deep_contacts_rest": n, "clean": bool}, ...]}

A URDF is clean when MuJoCo compiles it, no contact between two distinct bodies is deeper than
`--depth` (5 mm) at rest (every joint at 0), and none is with each movable joint swept over
`--states` (5) evenly spaced states of its range, the others at 0. Depths are MuJoCo's
`contact.dist` (negative: penetration) after `mj_forward`, on MuJoCo's collision geometry (the
convex hull of each collision mesh; physnap exports convex pieces, so the hull is the piece).

Choices:
- a file ending in `.xml` is MJCF and loads as it is (its meshdir is relative to it); any
  other file is URDF, whose meshes are found by injecting `<mujoco><compiler meshdir=URDF's folder strippath="false"/>`
  (filenames stay relative to the URDF, as URDF means them); an existing `<mujoco>` element is
  replaced.
- MuJoCo skips contacts between a body and its parent by default (`filterparent`); the check
  turns that filter off, since a drawer inside its cabinet is exactly the failure it is for.
- a physnap screw joint is exported as a prismatic + revolute pair (`joint_X_slide`,
  `joint_X_turn`); the pair is swept together, as one joint.
- a URDF MuJoCo refuses is not clean; its error is reported and the other files still run.

Exit status: 0 when every file was checked (clean or not), 2 on bad arguments, 3 when the
`mujoco` package is not importable (the message names the fix). `--probe` only imports
mujoco and prints its version.
"""

import argparse
import json
import os
import re
import sys


def load_mujoco():
    try:
        import mujoco  # noqa: F401
    except ImportError as e:
        sys.stderr.write(
            "sim_check.py: the Python package `mujoco` is not importable by "
            f"{sys.executable} ({e}); install it with `{sys.executable} -m pip install "
            "mujoco==4.0.0`, or point physnap at a Python that has it (--python / "
            "PHYSNAP_PYTHON)\n"
        )
        sys.exit(3)
    import mujoco

    return mujoco


def urdf_for_mujoco(path):
    """The URDF text with a <mujoco><compiler .../></mujoco> element that finds its meshes."""
    with open(path, encoding="utf-8") as f:
        text = f.read()
    folder = os.path.dirname(os.path.abspath(path))
    ext = (
        '<mujoco><compiler meshdir="{}" strippath="false" discardvisual="true" '
        'fusestatic="false"/></mujoco>'.format(folder.replace('"', "&quot;"))
    )
    text = re.sub(r"<mujoco>.*?</mujoco>", "", text, flags=re.S)
    m = re.search(r"<robot\b[^>]*>", text)
    if m is None:
        raise ValueError("no <robot> element")
    return text[: m.end()] + ext + text[m.end():]


def deepest(model, data, depth_limit):
    """(depth, body a, body b) of the deepest contact between distinct bodies, and the number of
    such contacts deeper than `depth_limit`."""
    best = (0.0, None, None)
    deep = 0
    for i in range(data.ncon):
        c = data.contact[i]
        b1 = int(model.geom_bodyid[c.geom1])
        b2 = int(model.geom_bodyid[c.geom2])
        if b1 == b2:
            continue
        depth = -float(c.dist)
        if depth > depth_limit:
            deep += 1
        if depth > best[0]:
            best = (depth, b1, b2)
    return best, deep


def body_name(mujoco, model, b):
    return mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"


def joint_groups(mujoco, model):
    """Movable joints as groups of MuJoCo joint ids (a screw's slide + turn pair is one)."""
    groups = {}
    for j in range(model.njnt):
        kinds = (int(mujoco.mjtJoint.mjJNT_HINGE), int(mujoco.mjtJoint.mjJNT_SLIDE))
        if int(model.jnt_type[j]) not in kinds:
            continue
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or f"joint{j}"
        key = re.sub(r"_(slide|turn)$", "", name)
        groups.setdefault(key, []).append(j)
    return groups


def check(mujoco, path, depth_limit, states):
    out = {
        "urdf": path,
        "compiled": False,
        "error": None,
        "bodies": 0,
        "joints": 0,
        "rest_depth": None,
        "sweep_depth": None,
        "deep_contacts_rest": 0,
        "worst": None,
        "clean": False,
    }
    try:
        if path.endswith(".xml"):
            model = mujoco.MjModel.from_xml_path(path)
        else:
            model = mujoco.MjModel.from_xml_string(urdf_for_mujoco(path))
    except Exception as e:  # MuJoCo raises ValueError on compile errors
        out["error"] = str(e).strip()
        return out
    out["compiled"] = True
    out["bodies"] = int(model.nbody)
    model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_FILTERPARENT)
    data = mujoco.MjData(model)
    worst = None

    def measure(qpos, joint, q):
        nonlocal worst
        data.qpos[:] = qpos
        mujoco.mj_forward(model, data)
        (d, b1, b2), deep = deepest(model, data, depth_limit)
        if b1 is not None and (worst is None or d > worst["depth"]):
            worst = {
                "depth": d,
                "bodies": [body_name(mujoco, model, b1), body_name(mujoco, model, b2)],
                "joint": joint,
                "q": q,
            }
        return d, deep

    rest = model.qpos0.copy()
    rest_depth, deep_rest = measure(rest, None, None)
    out["rest_depth"] = rest_depth
    out["deep_contacts_rest"] = deep_rest
    groups = joint_groups(mujoco, model)
    out["joints"] = len(groups)
    sweep = 0.0
    for name, ids in sorted(groups.items()):
        for k in range(states):
            f = k / (states - 1) if states > 1 else 0.0
            qpos = rest.copy()
            qs = []
            for j in ids:
                lo, hi = (float(x) for x in model.jnt_range[j])
                if not model.jnt_limited[j]:
                    lo, hi = 0.0, 0.0
                q = lo + f * (hi - lo)
                qpos[model.jnt_qposadr[j]] = q
                qs.append(q)
            d, _ = measure(qpos, name, qs if len(qs) > 1 else qs[0])
            sweep = max(sweep, d)
    out["sweep_depth"] = sweep
    out["worst"] = worst
    out["clean"] = rest_depth <= depth_limit and sweep <= depth_limit
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "urdf", nargs="*", help="URDF or MJCF (.xml) files (each with its meshes/ folder)"
    )
    ap.add_argument("--probe", action="store_true", help="only check that mujoco imports")
    ap.add_argument("--depth", type=float, default=0.005, help="deepest allowed contact (m)")
    ap.add_argument("--states", type=int, default=5, help="states per joint sweep")
    a = ap.parse_args()
    if a.states < 1 or not a.depth >= 0:
        ap.error("--states must be >= 1 and --depth >= 0")
    mujoco = load_mujoco()
    if a.probe:
        print(json.dumps({"format": "physnap.sim_check/v1", "mujoco": mujoco.__version__}))
        return
    if not a.urdf:
        ap.error("no URDF given")
    results = [check(mujoco, p, a.depth, a.states) for p in a.urdf]
    doc = {
        "format": "physnap.sim_check/v1",
        "mujoco": mujoco.__version__,
        "depth": a.depth,
        "states": a.states,
        "results": results,
    }
    json.dump(doc, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
