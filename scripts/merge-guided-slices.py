#!/usr/bin/env python3
"""Merge one-scan slices of `physnap eval guided` into one guided-table JSON.

Why this exists: the guided checks run one scan per process (`--skip-clouds i --max-clouds 1`),
many processes at a time, on this machine or on a lent device host. Each slice writes its own
`guided_table.json`. This script joins the slices of one command (same weights, block, seed set)
so that `scripts/compare-guided.py` can pool them.

What it does:
  - keeps the settings every slice shares (sampler, steps, loss scales, seed, ...) and refuses
    slices whose settings differ, naming the key and both values (the reference data's path
    may differ: slices from another machine read the same objects from another folder);
  - concatenates each row's `per_sample` in cloud order, and refuses a cloud seen twice;
  - drops the per-row statistics (medians, MMD, 1-NNA), which do not merge: recompute them from
    the samples with `scripts/compare-guided.py`;
  - records every slice's cloud index and command, and a note (`--note`).

Only the standard library. Reads and writes physnap.guided_table/v1.

Usage:
  scripts/merge-guided-slices.py --out merged.json [--note TEXT] r/v5r2_no_s1000_c*
  (each argument a slice directory holding guided_table.json, or the JSON file itself)
"""

import argparse
import json
import os
import sys

# Keys that legitimately differ between slices of one command.
PER_SLICE = {"clouds", "command", "skip_clouds", "rows"}
# Where each slice read its reference objects may differ (another machine, another path):
# settings are compared without it.
def comparable(key, value):
    if key == "references" and isinstance(value, dict):
        return {k: v for k, v in value.items() if k != "data"}
    return value


# Row keys that identify the row; everything else but per_sample is a statistic.
ROW_KEYS = ["variant", "category_aware", "guidance", "category_guidance", "category_guidance_below"]


def read(path):
    if os.path.isdir(path):
        path = os.path.join(path, "guided_table.json")
    with open(path) as f:
        table = json.load(f)
    if table.get("format") != "physnap.guided_table/v1":
        sys.exit(f"{path}: format {table.get('format')!r}, expected physnap.guided_table/v1")
    return path, table


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--note", default="")
    ap.add_argument("slices", nargs="+")
    a = ap.parse_args()

    tables = sorted((read(p) for p in a.slices), key=lambda pt: pt[1].get("skip_clouds", 0))
    first_path, first = tables[0]
    merged = {k: v for k, v in first.items() if k not in PER_SLICE}
    rows = {}
    order = []
    seen_clouds = {}
    slices = []
    for path, t in tables:
        for k, v in merged.items():
            if comparable(k, t.get(k)) != comparable(k, v):
                sys.exit(f"{path}: setting {k!r} is {t.get(k)!r}, but {first_path} has {v!r}")
        for cloud in t.get("clouds", []):
            if cloud in seen_clouds:
                sys.exit(f"{path}: cloud {cloud} is also in {seen_clouds[cloud]}")
            seen_clouds[cloud] = path
        slices.append({"cloud_index": t.get("skip_clouds", 0), "command": t.get("command", "")})
        for r in t["rows"]:
            key = tuple(json.dumps(r.get(k)) for k in ROW_KEYS)
            if key not in rows:
                rows[key] = {k: r.get(k) for k in ROW_KEYS} | {"per_sample": []}
                order.append(key)
            rows[key]["per_sample"].extend(r["per_sample"])
    merged["note"] = (
        "Merged from one-scan slices (--skip-clouds i --max-clouds 1) of the same command by "
        "scripts/merge-guided-slices.py; rows keep every sample (per_sample) but no row statistics: "
        "pool them with scripts/compare-guided.py." + (" " + a.note if a.note else "")
    )
    merged["slices"] = slices
    merged["rows"] = [rows[k] for k in order]
    with open(a.out, "w") as f:
        json.dump(merged, f, indent=1)
        f.write("\n")
    n = sum(len(r["per_sample"]) for r in merged["rows"])
    print(f"{a.out}: {len(slices)} slices, {len(seen_clouds)} clouds, {len(merged['rows'])} rows, {n} samples")


if __name__ == "__main__":
    main()
