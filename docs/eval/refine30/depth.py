#!/usr/bin/env python3
"""Intrusion depth of part-box pairs at rest (object.json files): for each pair whose boxes
intersect, the smallest per-axis overlap over the object's bounding-box diagonal; pairs where
one box lies (almost) inside the other (> 90 % of the smaller) are counted apart as nested."""
import glob, json, sys, math
for label, g in zip(sys.argv[1::2], sys.argv[2::2]):
    depths, nested, pairs = [], 0, 0
    for f in sorted(glob.glob(g)):
        parts = json.load(open(f))['parts']
        lo = [min(p['center'][k] - abs(p['half_extents'][k]) for p in parts) for k in range(3)]
        hi = [max(p['center'][k] + abs(p['half_extents'][k]) for p in parts) for k in range(3)]
        diag = math.dist(lo, hi)
        for i in range(len(parts)):
            for j in range(i + 1, len(parts)):
                a, b = parts[i], parts[j]; pairs += 1
                e = [max(0.0, min(a['center'][k] + abs(a['half_extents'][k]), b['center'][k] + abs(b['half_extents'][k])) - max(a['center'][k] - abs(a['half_extents'][k]), b['center'][k] - abs(b['half_extents'][k]))) for k in range(3)]
                vi = e[0] * e[1] * e[2]
                if vi <= 0: continue
                va = 8 * abs(math.prod(a['half_extents'])); vb = 8 * abs(math.prod(b['half_extents']))
                if vi > 0.9 * min(va, vb): nested += 1; continue
                depths.append(min(e) / diag)
    depths.sort(); n = len(depths)
    q = lambda p: depths[min(n - 1, int(p * n))] if n else float('nan')
    print(f'| {label} | {pairs} | {100*nested/pairs:.0f} % | {100*n/pairs:.0f} % | {q(0.25):.4f} / {q(0.5):.4f} / {q(0.75):.4f} |')
