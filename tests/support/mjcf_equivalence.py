#!/usr/bin/env python3
"""mjcf_equivalence.py: a physnap export's robot.urdf and model.xml are one model in MuJoCo.

Why it exists: physnap writes the same articulated object twice, as URDF and as MJCF, and
tests/mjcf.rs needs an engine to say that both compile (which also proves MuJoCo accepts the
inertials) and that they agree. Usage:

    mjcf_equivalence.py [--tol 1e-6] [--expected FILE] EXPORT_DIR [EXPORT_DIR ...]

For every export directory (robot.urdf, model.xml and meshes/ side by side, as `physnap export`
writes them) it compiles robot.urdf, with the `<mujoco><compiler meshdir=... strippath="false"
discardvisual="true" fusestatic="false"/></mujoco>` element scripts/sim_check.py injects, and
model.xml as it is (from its path, so its own `meshdir="meshes"` resolves), then checks:

- bodies: model.xml's bodies are the URDF's links, by name, except the URDF's
  `<child>_screw_helper` links (MJCF puts a screw's two joints in one body);
- joints: the same names and types, ranges, damping, frictionloss and actuator force ranges;
- inertials: every body's mass and principal moments;
- collision geoms: as many per body in both (model.xml's group-3 geoms; the URDF's, visuals
  discarded);
- poses: with every joint at the fractions 0, .25, .5, .75 and 1 of its range (one fraction
  for all joints at a time), after mj_forward, every body's world position, orientation and
  centre of mass, and every collision geom's world position, agree within --tol (1e-6 m or
  quaternion units; q and -q are the same orientation);
- with --expected FILE (JSON: {"fractions": [...], "poses": {"<dir>": {"<body>": [[x, y, z,
  qw, qx, qy, qz], ... one per fraction]}}}), model.xml's body poses also agree with the poses
  physnap's own kinematics gives (keyed by the directory as given on the command line).

Prints one JSON document, {"format": "physnap.mjcf_equivalence/v1", "mujoco": VERSION,
"results": [{"dir": D, "ok": bool, "errors": [str, ...], "bodies": n, "joints": n,
"max_pose_error": e}, ...]}. Exit status: 0 when every directory passed, 1 when one failed,
2 on bad arguments, 3 when `mujoco` is not importable.
"""

import argparse
import json
import os
import re
import sys

# The URDF is loaded exactly as the sim-clean check loads it (scripts/sim_check.py).
sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts"))
from sim_check import urdf_for_mujoco  # noqa: E402

FRACTIONS = [0.0, 0.25, 0.5, 0.75, 1.0]


def load_mujoco():
    try:
        import mujoco
    except ImportError as e:
        sys.stderr.write(f"mjcf_equivalence.py: cannot import mujoco with {sys.executable}: {e}\n")
        sys.exit(3)
    return mujoco


def names(mujoco, model, kind, n):
    return {mujoco.mj_id2name(model, kind, i): i for i in range(n)}


def quat_error(a, b):
    d1 = max(abs(x - y) for x, y in zip(a, b))
    d2 = max(abs(x + y) for x, y in zip(a, b))
    return min(d1, d2)


def vec_error(a, b):
    return max(abs(x - y) for x, y in zip(a, b))


def collision_geoms(model, body, mjcf):
    """Collision geom ids of a body in order: group 3 in model.xml, all geoms in the URDF."""
    out = []
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) != body:
            continue
        if mjcf and int(model.geom_group[g]) != 3:
            continue
        out.append(g)
    return out


def check(mujoco, d, tol, expected):
    errors = []
    res = {"dir": d, "ok": False, "errors": errors, "bodies": 0, "joints": 0,
           "max_pose_error": None}
    try:
        u = mujoco.MjModel.from_xml_string(urdf_for_mujoco(os.path.join(d, "robot.urdf")))
    except Exception as e:  # MuJoCo raises ValueError on compile errors
        errors.append(f"robot.urdf does not compile: {str(e).strip()}")
    try:
        m = mujoco.MjModel.from_xml_path(os.path.join(d, "model.xml"))
    except Exception as e:
        errors.append(f"model.xml does not compile: {str(e).strip()}")
    if errors:
        return res
    B, J = mujoco.mjtObj.mjOBJ_BODY, mujoco.mjtObj.mjOBJ_JOINT
    ub, mb = names(mujoco, u, B, u.nbody), names(mujoco, m, B, m.nbody)
    uj, mj = names(mujoco, u, J, u.njnt), names(mujoco, m, J, m.njnt)
    res["bodies"], res["joints"] = m.nbody - 1, m.njnt
    helpers = {n for n in ub if n.endswith("_screw_helper")}
    if set(ub) - helpers != set(mb):
        errors.append(f"bodies differ: urdf {sorted(set(ub) - helpers)} mjcf {sorted(mb)}")
    if set(uj) != set(mj):
        errors.append(f"joints differ: urdf {sorted(uj)} mjcf {sorted(mj)}")
    if errors:
        return res
    for n, j in mj.items():
        k = uj[n]
        if int(m.jnt_type[j]) != int(u.jnt_type[k]):
            errors.append(f"joint {n}: type {int(m.jnt_type[j])} vs urdf {int(u.jnt_type[k])}")
        for what, a, b in [
            ("range", m.jnt_range[j], u.jnt_range[k]),
            ("damping", [m.dof_damping[m.jnt_dofadr[j]]], [u.dof_damping[u.jnt_dofadr[k]]]),
            ("frictionloss", [m.dof_frictionloss[m.jnt_dofadr[j]]],
             [u.dof_frictionloss[u.jnt_dofadr[k]]]),
            ("actuatorfrcrange", m.jnt_actfrcrange[j], u.jnt_actfrcrange[k]),
        ]:
            if vec_error(a, b) > 1e-12:
                errors.append(f"joint {n}: {what} {list(a)} vs urdf {list(b)}")
    for n, b in mb.items():
        if b == 0:
            continue
        k = ub[n]
        mass_m, mass_u = float(m.body_mass[b]), float(u.body_mass[k])
        if abs(mass_m - mass_u) > 1e-12 * max(1.0, mass_u):
            errors.append(f"body {n}: mass {mass_m} vs urdf {mass_u}")
        im, iu = sorted(m.body_inertia[b]), sorted(u.body_inertia[k])
        if vec_error(im, iu) > 1e-9 * max(iu):
            errors.append(f"body {n}: principal moments {im} vs urdf {iu}")
        gm, gu = collision_geoms(m, b, True), collision_geoms(u, k, False)
        if len(gm) != len(gu):
            errors.append(f"body {n}: {len(gm)} collision geoms vs urdf {len(gu)}")
    md, ud = mujoco.MjData(m), mujoco.MjData(u)
    worst = 0.0
    for fi, f in enumerate(FRACTIONS):
        for n, j in mj.items():
            k = uj[n]
            lo, hi = u.jnt_range[k]
            q = lo + f * (hi - lo)
            md.qpos[m.jnt_qposadr[j]] = q
            ud.qpos[u.jnt_qposadr[k]] = q
        mujoco.mj_forward(m, md)
        mujoco.mj_forward(u, ud)
        for n, b in mb.items():
            k = ub[n]
            e = max(
                vec_error(md.xpos[b], ud.xpos[k]),
                quat_error(md.xquat[b], ud.xquat[k]),
                vec_error(md.xipos[b], ud.xipos[k]),
            )
            for gm, gu in zip(collision_geoms(m, b, True), collision_geoms(u, k, False)):
                e = max(e, vec_error(md.geom_xpos[gm], ud.geom_xpos[gu]))
            want = (expected or {}).get(n)
            if want is not None:
                w = want[fi]
                e = max(e, vec_error(md.xpos[b], w[:3]), quat_error(md.xquat[b], w[3:]))
            elif expected is not None and b != 0:
                errors.append(f"body {n}: not in the expected poses")
            worst = max(worst, e)
            if e > tol:
                errors.append(f"fraction {f}: body {n} differs by {e}")
    if expected is not None:
        missing = sorted(set(expected) - set(mb))
        if missing:
            errors.append(f"expected bodies missing in model.xml: {missing}")
    res["max_pose_error"] = worst
    res["ok"] = not errors
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("dirs", nargs="+")
    ap.add_argument("--tol", type=float, default=1e-6)
    ap.add_argument("--expected")
    a = ap.parse_args()
    mujoco = load_mujoco()
    expected = {}
    if a.expected:
        with open(a.expected, encoding="utf-8") as f:
            doc = json.load(f)
        if doc.get("fractions") != FRACTIONS:
            sys.stderr.write(f"--expected: fractions must be {FRACTIONS}\n")
            sys.exit(2)
        expected = doc["poses"]
    results = [
        check(mujoco, d, a.tol, expected.get(d) if a.expected else None) for d in a.dirs
    ]
    print(json.dumps({"format": "physnap.mjcf_equivalence/v1", "mujoco": mujoco.__version__,
                      "results": results}, indent=1))
    sys.exit(0 if all(r["ok"] for r in results) else 1)


if __name__ == "__main__":
    main()
