#!/usr/bin/env python3
"""MJCF -> URDF + OBJ meshes, for physnap's URDF importer (`physnap data import --urdf`).

Why it exists: several real articulated assets (LIBERO-PRO cabinets and fridge, robosuite
doors) are MJCF. MuJoCo itself resolves what is hard to get right by hand (defaults and
classes, angle units, euler/axis-angle/quat frames, mesh scale, MuJoCo's binary .msh meshes),
so this script compiles the file with `mujoco.MjModel.from_xml_path` (PyPI `mujoco`, tested
with 4.0.0) and writes what the compiled model says:

* one URDF link per body (the world body is the root link `world`), named after the body
  (`body<N>` when unnamed); a body without joints hangs from its parent by a fixed joint;
* a body with one hinge -> `revolute` (its `range`, when the range is not empty, even with
  limited="false"; else `continuous`), one slide -> `prismatic` (a range is required); the
  link frame sits on the joint's `pos`, axes are the compiled `jnt_axis`;
* a free joint on a top-level body (a loose object) becomes fixed; a free joint deeper in
  the tree, a ball joint, or a body with several joints is refused (exit 2, a message naming
  the body): URDF has one joint per link and physnap one movable joint per part;
* geoms: contype = conaffinity = 0 (MuJoCo's visual-only convention) -> `<visual>`,
  others -> `<collision>`; when a model has no visual-only geom, every geom is both.
  sphere/box/cylinder -> URDF primitives; mesh -> OBJ from the compiled vertex and face
  arrays (already scaled and in the geom frame); capsule and ellipsoid -> generated OBJ;
  planes and height fields are skipped (noted);
* before compiling, appearance-only and non-MuJoCo markup is removed from a copy of the file
  (written next to it, deleted after): `<texture>` elements and material `texture`
  references (LIBERO files repeat texture names, which MuJoCo rejects) and LIBERO's own
  `<region>` element; geometry, joints and defaults are untouched;
* output is deterministic: fixed float formatting, bodies/geoms in model order.

Usage: mjcf_to_urdf.py MODEL.xml OUT_DIR [--name NAME] [--assume-angle radian|degree]
Writes OUT_DIR/NAME.urdf (NAME defaults to the file stem) and OUT_DIR/NAME_meshes/*.obj;
prints one JSON line describing the result.
"""

import argparse
import json
import math
import os
import sys
import xml.etree.ElementTree as ET

import mujoco
import numpy as np


def fmt(x):
    """Deterministic float text (9 significant digits, no negative zero)."""
    v = float(x)
    if abs(v) < 1e-12:
        v = 0.0
    return "%.9g" % v


def vec(v):
    return " ".join(fmt(x) for x in v)


def quat_to_mat(q):
    m = np.zeros(9)
    mujoco.mju_quat2Mat(m, np.asarray(q, dtype=np.float64))
    return m.reshape(3, 3)


def mat_to_rpy(r):
    """URDF rpy (R = Rz(y) Ry(p) Rx(r))."""
    sy = -r[2, 0]
    if abs(sy) >= 1.0 - 1e-12:
        pitch = math.copysign(math.pi / 2, sy)
        roll = math.atan2(-r[1, 2], r[1, 1]) if sy > 0 else math.atan2(-r[1, 2], r[1, 1])
        yaw = 0.0
    else:
        pitch = math.asin(sy)
        roll = math.atan2(r[2, 1], r[2, 2])
        yaw = math.atan2(r[1, 0], r[0, 0])
    return (roll, pitch, yaw)


def pose(pos, rot):
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = pos
    return t


def origin_xml(t):
    return '<origin xyz="%s" rpy="%s"/>' % (vec(t[:3, 3]), vec(mat_to_rpy(t[:3, :3])))


class Refused(Exception):
    pass


def uv_ellipsoid(radii, n_lon=24, n_lat=12):
    verts, faces = [], []
    verts.append((0.0, 0.0, -radii[2]))
    for i in range(1, n_lat):
        th = -math.pi / 2 + math.pi * i / n_lat
        for j in range(n_lon):
            ph = 2 * math.pi * j / n_lon
            verts.append((radii[0] * math.cos(th) * math.cos(ph),
                          radii[1] * math.cos(th) * math.sin(ph),
                          radii[2] * math.sin(th)))
    verts.append((0.0, 0.0, radii[2]))
    top = len(verts) - 1
    ring = lambda i, j: 1 + (i - 1) * n_lon + (j % n_lon)
    for j in range(n_lon):
        faces.append((0, ring(1, j + 1), ring(1, j)))
        faces.append((top, ring(n_lat - 1, j), ring(n_lat - 1, j + 1)))
    for i in range(1, n_lat - 1):
        for j in range(n_lon):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)
            faces.append((a, b, c))
            faces.append((a, c, d))
    return verts, faces


def capsule(radius, half, n_lon=24, n_lat=12):
    """Capsule along Z: a sphere split at the equator, hemispheres moved apart."""
    verts, faces = uv_ellipsoid((radius, radius, radius), n_lon, n_lat)
    verts = [(x, y, z + (half if z > 1e-12 else (-half if z < -1e-12 else 0.0))) for x, y, z in verts]
    return verts, faces


def write_obj(path, verts, faces):
    with open(path, "w") as f:
        for v in verts:
            f.write("v %s\n" % vec(v))
        for t in faces:
            f.write("f %d %d %d\n" % (t[0] + 1, t[1] + 1, t[2] + 1))


def compile_model(xml_path, assume_angle=None):
    """Compile `xml_path` after dropping textures and LIBERO's <region> (see the header).

    `assume_angle` ("radian"/"degree") is the angle unit for a file whose <compiler> does not
    say: robosuite's object files are compiled inside robosuite's world, which sets radians,
    while MuJoCo's own default is degrees.
    """
    tree = ET.parse(xml_path)
    dropped = 0
    if assume_angle:
        compilers = [c for c in tree.getroot().iter("compiler") if "angle" in c.attrib]
        if not compilers:
            c = tree.getroot().find("compiler")
            if c is None:
                c = ET.Element("compiler")
                tree.getroot().insert(0, c)
            c.set("angle", assume_angle)
            dropped += 1
    for parent in tree.iter():
        for child in list(parent):
            if child.tag in ("texture", "region"):
                parent.remove(child)
                dropped += 1
        if parent.tag == "material" and "texture" in parent.attrib:
            del parent.attrib["texture"]
    if dropped == 0:
        return mujoco.MjModel.from_xml_path(xml_path)
    tmp = os.path.join(os.path.dirname(os.path.abspath(xml_path)),
                       ".physnap_tmp_%d_%s" % (os.getpid(), os.path.basename(xml_path)))
    tree.write(tmp)
    try:
        return mujoco.MjModel.from_xml_path(tmp)
    finally:
        os.remove(tmp)


def convert(xml_path, out_dir, name, assume_angle=None):
    m = compile_model(xml_path, assume_angle)
    os.makedirs(out_dir, exist_ok=True)
    mesh_dir_name = name + "_meshes"
    mesh_dir = os.path.join(out_dir, mesh_dir_name)
    notes = []

    def body_name(b):
        n = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b)
        if b == 0:
            return "world"
        return n if n else "body%d" % b

    names = [body_name(b) for b in range(m.nbody)]
    seen = {}
    for b, n in enumerate(names):
        if n in seen:
            names[b] = "%s_%d" % (n, b)
        seen[names[b]] = b

    # World pose of every body at the reference configuration (compiled body_pos/quat).
    world = [np.eye(4) for _ in range(m.nbody)]
    for b in range(1, m.nbody):
        p = m.body_parentid[b]
        world[b] = world[p] @ pose(m.body_pos[b], quat_to_mat(m.body_quat[b]))

    # Link frame per body: the body frame moved onto its joint position.
    link = [w.copy() for w in world]
    joint_of = [None] * m.nbody
    for b in range(1, m.nbody):
        nj, adr = m.body_jntnum[b], m.body_jntadr[b]
        if nj == 0:
            continue
        if nj > 1:
            types = [int(m.jnt_type[adr + k]) for k in range(nj)]
            raise Refused("body %r has %d joints (types %s): URDF and physnap need one joint per body"
                          % (names[b], nj, types))
        j = adr
        jt = int(m.jnt_type[j])
        if jt == mujoco.mjtJoint.mjJNT_FREE:
            if m.body_parentid[b] != 0:
                raise Refused("body %r has a free joint below the top level" % names[b])
            notes.append("free joint of top-level body %r imported as fixed" % names[b])
            continue
        if jt == mujoco.mjtJoint.mjJNT_BALL:
            raise Refused("body %r has a ball joint (not supported)" % names[b])
        link[b] = world[b] @ pose(m.jnt_pos[j], np.eye(3))
        joint_of[b] = j

    any_visual = any(m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0 for g in range(m.ngeom))
    written_meshes = {}
    geoms_of = [[] for _ in range(m.nbody)]
    for g in range(m.ngeom):
        b = int(m.geom_bodyid[g])
        gt = int(m.geom_type[g])
        visual_only = m.geom_contype[g] == 0 and m.geom_conaffinity[g] == 0
        roles = ["visual", "collision"] if not any_visual else (["visual"] if visual_only else ["collision"])
        if "visual" in roles and m.geom_rgba[g][3] == 0 and any_visual:
            continue
        # Geom pose in the link frame.
        t = np.linalg.inv(link[b]) @ world[b] @ pose(m.geom_pos[g], quat_to_mat(m.geom_quat[g]))
        size = m.geom_size[g]
        if gt == mujoco.mjtGeom.mjGEOM_SPHERE:
            shape = '<sphere radius="%s"/>' % fmt(size[0])
        elif gt == mujoco.mjtGeom.mjGEOM_BOX:
            shape = '<box size="%s"/>' % vec(2 * size[:3])
        elif gt == mujoco.mjtGeom.mjGEOM_CYLINDER:
            shape = '<cylinder radius="%s" length="%s"/>' % (fmt(size[0]), fmt(2 * size[1]))
        elif gt in (mujoco.mjtGeom.mjGEOM_CAPSULE, mujoco.mjtGeom.mjGEOM_ELLIPSOID):
            os.makedirs(mesh_dir, exist_ok=True)
            fname = "geom%d.obj" % g
            if gt == mujoco.mjtGeom.mjGEOM_CAPSULE:
                v, f = capsule(size[0], size[1])
            else:
                v, f = uv_ellipsoid(size[:3])
            write_obj(os.path.join(mesh_dir, fname), v, f)
            shape = '<mesh filename="%s/%s"/>' % (mesh_dir_name, fname)
        elif gt == mujoco.mjtGeom.mjGEOM_MESH:
            mid = int(m.geom_dataid[g])
            if mid not in written_meshes:
                os.makedirs(mesh_dir, exist_ok=True)
                mname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_MESH, mid) or "mesh%d" % mid
                fname = "%d_%s.obj" % (mid, "".join(c if c.isalnum() or c in "-_." else "_" for c in mname))
                va, vn = m.mesh_vertadr[mid], m.mesh_vertnum[mid]
                fa, fnum = m.mesh_faceadr[mid], m.mesh_facenum[mid]
                write_obj(os.path.join(mesh_dir, fname), m.mesh_vert[va:va + vn], m.mesh_face[fa:fa + fnum])
                written_meshes[mid] = fname
            shape = '<mesh filename="%s/%s"/>' % (mesh_dir_name, written_meshes[mid])
        else:
            notes.append("geom %d of body %r: type %d skipped" % (g, names[b], gt))
            continue
        for role in roles:
            geoms_of[b].append((role, t, shape))

    lines = ['<?xml version="1.0"?>', '<!-- converted by physnap scripts/mjcf_to_urdf.py from %s with mujoco %s -->'
             % (os.path.basename(xml_path), mujoco.__version__), '<robot name="%s">' % name]
    for b in range(m.nbody):
        lines.append('  <link name="%s">' % names[b])
        for role, t, shape in geoms_of[b]:
            lines.append("    <%s>\n      %s\n      <geometry>%s</geometry>\n    </%s>" % (role, origin_xml(t), shape, role))
        lines.append("  </link>")
    joints = []
    for b in range(1, m.nbody):
        p = int(m.body_parentid[b])
        rel = np.linalg.inv(link[p]) @ link[b]
        j = joint_of[b]
        if j is None:
            lines.append('  <joint name="%s_fixed" type="fixed">\n    %s\n    <parent link="%s"/>\n    <child link="%s"/>\n  </joint>'
                         % (names[b], origin_xml(rel), names[p], names[b]))
            continue
        jname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, j) or "joint%d" % j
        lo, hi = float(m.jnt_range[j][0]), float(m.jnt_range[j][1])
        jt = int(m.jnt_type[j])
        if jt == mujoco.mjtJoint.mjJNT_HINGE:
            kind = "revolute" if hi - lo > 1e-9 else "continuous"
        else:
            if not hi - lo > 1e-9:
                raise Refused("slide joint %r of body %r has no range" % (jname, names[b]))
            kind = "prismatic"
        limit = '\n    <limit lower="%s" upper="%s" effort="0" velocity="0"/>' % (fmt(lo), fmt(hi)) if kind != "continuous" else ""
        lines.append('  <joint name="%s" type="%s">\n    %s\n    <parent link="%s"/>\n    <child link="%s"/>\n    <axis xyz="%s"/>%s\n  </joint>'
                     % (jname, kind, origin_xml(rel), names[p], names[b], vec(m.jnt_axis[j]), limit))
        joints.append({"name": jname, "type": kind, "body": names[b], "range": [lo, hi]})
    lines.append("</robot>")
    urdf_path = os.path.join(out_dir, name + ".urdf")
    with open(urdf_path, "w") as f:
        f.write("\n".join(lines) + "\n")
    return {"urdf": urdf_path, "bodies": m.nbody - 1, "joints": joints, "meshes": len(written_meshes), "notes": notes}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model")
    ap.add_argument("out_dir")
    ap.add_argument("--name", default=None)
    ap.add_argument("--assume-angle", choices=["radian", "degree"], default=None,
                    help="angle unit for a file whose <compiler> does not set one (MuJoCo: degree)")
    a = ap.parse_args()
    name = a.name or os.path.splitext(os.path.basename(a.model))[0]
    try:
        info = convert(a.model, a.out_dir, name, a.assume_angle)
    except Refused as e:
        print("mjcf_to_urdf: %s: refused: %s" % (a.model, e), file=sys.stderr)
        sys.exit(2)
    print(json.dumps(info, sort_keys=True))


if __name__ == "__main__":
    main()
