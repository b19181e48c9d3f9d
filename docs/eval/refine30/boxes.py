#!/usr/bin/env python3
"""Rest-state box layouts of articulated objects: how often and how deep part boxes intersect.

Why this exists: session 37 asked whether generated samples penetrate because their part boxes
sit closer together than the data's (EVALUATION.md, top section). Standard library only.

Per pair of parts (boxes [centre - |half|, centre + |half|]):
  ratio = intersection volume / smaller box volume
  nested: ratio > 0.9; partly intersecting: 0 < ratio <= 0.9, with
  depth = smallest per-axis overlap / diagonal of the object's bounding box

usage:
  boxes.py LABEL GLOB [LABEL GLOB ...]    object.json files (physnap.object/v1)
  boxes.py --graph LABEL DATA             the test split's graph.npy of a `data import` folder
"""
import array
import ast
import glob
import json
import math
import struct
import sys

NODE_DIM, K = 135, 8  # graph.npy: existence, half-extents b (3), centre t (3), latent (128)


def from_object(path):
    """(centre, half-extents) of each part of an object.json."""
    return [(p['center'], p['half_extents']) for p in json.load(open(path))['parts']]


def from_graph(path):
    """(centre, half-extents) of each existing node of a graph.npy (float32, nodes first)."""
    raw = open(path, 'rb').read()
    header = struct.unpack('<H', raw[8:10])[0]
    a = array.array('f')
    a.frombytes(raw[10 + header:])
    nodes = [a[k * NODE_DIM:(k + 1) * NODE_DIM] for k in range(K)]
    return [(list(n[4:7]), list(n[1:4])) for n in nodes if n[0] > 0.5]


def pairs(parts):
    """(ratio, depth) of every part pair."""
    lo = [min(c[k] - abs(h[k]) for c, h in parts) for k in range(3)]
    hi = [max(c[k] + abs(h[k]) for c, h in parts) for k in range(3)]
    diag = max(math.dist(lo, hi), 1e-12)
    out = []
    for i in range(len(parts)):
        for j in range(i + 1, len(parts)):
            (ca, ha), (cb, hb) = parts[i], parts[j]
            e = [max(0.0, min(ca[k] + abs(ha[k]), cb[k] + abs(hb[k]))
                     - max(ca[k] - abs(ha[k]), cb[k] - abs(hb[k]))) for k in range(3)]
            smaller = min(8 * abs(math.prod(ha)), 8 * abs(math.prod(hb)))
            out.append((math.prod(e) / max(smaller, 1e-12), min(e) / diag))
    return out


def row(label, objects):
    """One table row over a list of objects (each a list of (centre, half-extents))."""
    ps = [p for parts in objects for p in pairs(parts)]
    n = max(len(ps), 1)
    share = lambda cond: f'{100 * sum(1 for p in ps if cond(p)) / n:.0f} %'
    worst = [max((r for r, _ in pairs(parts)), default=0.0) for parts in objects]
    partial = sorted(d for r, d in ps if 0 < r <= 0.9)
    q = lambda f: f'{partial[min(len(partial) - 1, int(f * len(partial)))]:.4f}' if partial else '—'
    return (f'| {label} | {len(objects)} | {len(ps)} | '
            + ' / '.join(share(lambda p, t=t: p[0] > t) for t in (0, 0.01, 0.1, 0.5))
            + f' | {100 * sum(w > 0.1 for w in worst) / max(len(objects), 1):.0f} % | '
            + f'{share(lambda p: p[0] > 0.9)} | {share(lambda p: 0 < p[0] <= 0.9)} | '
            + f'{q(0.25)} / {q(0.5)} / {q(0.75)} |')


def main(args):
    print('| set | objects | pairs | intersecting > 0 / > 1 % / > 10 % / > 50 % of the smaller box '
          '| objects with a pair > 10 % | nested (> 90 %) | partly intersecting '
          '| their depth / object diagonal, quartiles |')
    print('|---|---|---|---|---|---|---|---|')
    if args[:1] == ['--graph']:
        label, data = args[1], args[2]
        test = json.load(open(f'{data}/dataset.json'))['splits']['test']
        print(row(label, [from_graph(f'{data}/objects/{n}/graph.npy') for n in test]))
        return
    for label, pattern in zip(args[::2], args[1::2]):
        print(row(label, [from_object(f) for f in sorted(glob.glob(pattern))]))


if __name__ == '__main__':
    main(sys.argv[1:])
