#!/usr/bin/env python3
"""Rest-state box overlaps of objects (object.json files): per part pair, the intersection volume
of the two boxes over the smaller box's volume. usage: boxes.py LABEL GLOB [LABEL GLOB ...]"""
import glob, json, sys, statistics as st
def ratios(path):
    parts = json.load(open(path))['parts']
    out = []
    for i in range(len(parts)):
        for j in range(i + 1, len(parts)):
            a, b = parts[i], parts[j]
            v, e = 1.0, []
            for k in range(3):
                lo = max(a['center'][k] - abs(a['half_extents'][k]), b['center'][k] - abs(b['half_extents'][k]))
                hi = min(a['center'][k] + abs(a['half_extents'][k]), b['center'][k] + abs(b['half_extents'][k]))
                e.append(max(0.0, hi - lo))
            va = 8 * abs(a['half_extents'][0] * a['half_extents'][1] * a['half_extents'][2])
            vb = 8 * abs(b['half_extents'][0] * b['half_extents'][1] * b['half_extents'][2])
            vi = e[0] * e[1] * e[2]
            out.append(vi / max(min(va, vb), 1e-12))
    return out
args = sys.argv[1:]
print('| set | objects | pairs | pairs overlapping > 0 / > 1 % / > 10 % / > 50 % of the smaller box | objects with a pair > 10 % | mean parts |')
print('|---|---|---|---|---|---|')
for label, g in zip(args[::2], args[1::2]):
    files = sorted(glob.glob(g))
    allr, objmax, nparts = [], [], []
    for f in files:
        r = ratios(f)
        allr += r
        objmax.append(max(r) if r else 0)
        nparts.append(len(json.load(open(f))['parts']))
    n = len(allr)
    sh = lambda t: f'{100 * sum(x > t for x in allr) / n:.0f} %'
    print(f'| {label} | {len(files)} | {n} | {sh(0)} / {sh(0.01)} / {sh(0.1)} / {sh(0.5)} | {100 * sum(m > 0.1 for m in objmax) / len(files):.0f} % | {st.mean(nparts):.2f} |')
