#!/usr/bin/env python3
"""Compare one Table 1 row between two samplers from `physnap eval guided` JSON outputs.

Why this exists: issue 5 asks that the default fast sampler keep guidance quality "within 10 %"
of the paper's 1000-step sampler. The collision metrics (E_pen, E_mob) are heavy-tailed: most
samples are 0 or ~1e-6 and one overlapping sample in ten decides the mean. A ratio of two means
over 10-20 samples therefore says little on its own; this script pools every sample of the row
from any number of runs (deduplicated by cloud and seed) and reports, per metric:

  mean_A / mean_B with a 95 % percentile-bootstrap interval (resampling each side's samples,
  10,000 draws, fixed seed), the medians, the share of samples above 0 and above 1e-4, and —
  over the (cloud, seed) pairs both sides ran, e.g. two weights on the same scans and seeds —
  on how many pairs A is lower than B.

Only the standard library; reads `rows[*].per_sample` (physnap.guided_table/v1).

Usage:
  scripts/compare-guided.py --a default1.json default2.json --b ddpm1.json ddpm2.json \
      --variant pc+pen+mob --aware no [--label-a default --label-b "DDPM 1000"] [--common]
"""

import argparse
import json
import random
import statistics
import sys

METRICS = ["e_pc", "d_pc", "e_pen", "e_mob", "o_mesh", "id_gt"]


def load(paths, variant, aware):
    """Every non-diverged sample of the row, first occurrence of each (cloud, seed) kept."""
    seen = {}
    diverged = 0
    for p in paths:
        with open(p) as f:
            table = json.load(f)
        if table.get("format") != "physnap.guided_table/v1":
            sys.exit(f"{p}: format {table.get('format')!r}, expected physnap.guided_table/v1")
        rows = [
            r
            for r in table["rows"]
            if r["variant"] == variant and r["category_aware"] == aware
        ]
        if not rows:
            sys.exit(f"{p}: no row variant={variant} category_aware={aware}")
        if "per_sample" not in rows[0]:
            sys.exit(f"{p}: row {variant} has no per_sample records (written before they existed)")
        for s in rows[0]["per_sample"]:
            if s.get("diverged"):
                diverged += 1
                continue
            seen.setdefault((s["cloud"], s["seed"]), s)
    return list(seen.values()), diverged


def boot_ratio(a, b, rng, draws=10000):
    """95 % percentile interval of mean(a*)/mean(b*) over bootstrap resamples."""
    ratios = []
    for _ in range(draws):
        ma = statistics.fmean(rng.choices(a, k=len(a)))
        mb = statistics.fmean(rng.choices(b, k=len(b)))
        if mb > 0:
            ratios.append(ma / mb)
    ratios.sort()
    if not ratios:
        return float("nan"), float("nan")
    return ratios[int(0.025 * len(ratios))], ratios[int(0.975 * len(ratios)) - 1]


def share(v, t):
    """Percentage of values above t."""
    return f"{100 * sum(x > t for x in v) / len(v):.0f} %"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", nargs="+", required=True, help="runs of sampler A (JSON)")
    ap.add_argument("--b", nargs="+", required=True, help="runs of sampler B (JSON)")
    ap.add_argument("--variant", default="pc+pen+mob")
    ap.add_argument("--aware", choices=["yes", "no"], default="no")
    ap.add_argument("--label-a", default="A")
    ap.add_argument("--label-b", default="B")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--common",
        action="store_true",
        help="keep only the (cloud, seed) pairs both sides ran (e.g. a slice against a full run)",
    )
    args = ap.parse_args()
    aware = args.aware == "yes"
    a, da = load(args.a, args.variant, aware)
    b, db = load(args.b, args.variant, aware)
    if args.common:
        ka = {(s["cloud"], s["seed"]) for s in a}
        kb = {(s["cloud"], s["seed"]) for s in b}
        a = [s for s in a if (s["cloud"], s["seed"]) in kb]
        b = [s for s in b if (s["cloud"], s["seed"]) in ka]
        if not a:
            sys.exit("--common: the two sides share no (cloud, seed) pair")
    rng = random.Random(args.seed)
    print(
        f"{args.variant}, category-aware {args.aware}: "
        f"{args.label_a} n={len(a)} (diverged {da}), {args.label_b} n={len(b)} (diverged {db})"
    )
    print(
        f"| metric | mean {args.label_a} | mean {args.label_b} | ratio A/B [95 % CI] "
        f"| median A / B | > 0 A / B | > 1e-4 A / B | A < B (paired) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    by_key = {(s["cloud"], s["seed"]): s for s in b}
    for m in METRICS:
        va = [s[m] for s in a if s.get(m) is not None]
        vb = [s[m] for s in b if s.get(m) is not None]
        if not va or not vb:
            continue
        ma, mb = statistics.fmean(va), statistics.fmean(vb)
        lo, hi = boot_ratio(va, vb, rng)
        ratio = ma / mb if mb > 0 else float("inf")
        pairs = []
        for s in a:
            t = by_key.get((s["cloud"], s["seed"]))
            if t is not None and s.get(m) is not None and t.get(m) is not None:
                pairs.append((s[m], t[m]))
        lower = sum(x < y for x, y in pairs)
        print(
            f"| {m} | {ma:.3g} | {mb:.3g} | {ratio:.2f} [{lo:.2f}, {hi:.2f}] "
            f"| {statistics.median(va):.2g} / {statistics.median(vb):.2g} "
            f"| {share(va, 0)} / {share(vb, 0)} | {share(va, 1e-4)} / {share(vb, 1e-4)} "
            f"| {lower} / {len(pairs)} |"
        )


if __name__ == "__main__":
    main()
