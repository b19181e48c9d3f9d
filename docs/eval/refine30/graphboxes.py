#!/usr/bin/env python3
"""Box overlaps of the test objects in the representation the denoiser learns (graph.npy: existence,
half-extents b, centre t per node), as boxes.py measures object.json files."""
import json, struct, ast, array, sys
def npy(p):
    b = open(p, 'rb').read()
    hl = struct.unpack('<H', b[8:10])[0]
    a = array.array('f'); a.frombytes(b[10 + hl:]); return a
d = json.load(open(sys.argv[1] + '/dataset.json'))
allr, objmax = [], []
for n in d['splits']['test']:
    a = npy(f'{sys.argv[1]}/objects/{n}/graph.npy')
    parts = [a[k * 135:(k + 1) * 135] for k in range(8) if a[k * 135] > 0.5]
    r = []
    for i in range(len(parts)):
        for j in range(i + 1, len(parts)):
            p, q = parts[i], parts[j]
            e = [max(0.0, min(p[4+k] + abs(p[1+k]), q[4+k] + abs(q[1+k])) - max(p[4+k] - abs(p[1+k]), q[4+k] - abs(q[1+k]))) for k in range(3)]
            vp = 8 * abs(p[1] * p[2] * p[3]); vq = 8 * abs(q[1] * q[2] * q[3])
            r.append(e[0] * e[1] * e[2] / max(min(vp, vq), 1e-12))
    allr += r; objmax.append(max(r) if r else 0)
n = len(allr); sh = lambda t: f'{100 * sum(x > t for x in allr) / n:.0f} %'
print(f'| data_test (graph.npy) | {len(objmax)} | {n} | {sh(0)} / {sh(0.01)} / {sh(0.1)} / {sh(0.5)} | {100 * sum(m > 0.1 for m in objmax) / len(objmax):.0f} % |')
