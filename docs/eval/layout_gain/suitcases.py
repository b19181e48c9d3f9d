#!/usr/bin/env python3
"""Suitcase layouts of generated samples against the test split's suitcases.

    physnap generate --weights W --category Suitcase --samples 16 --seed 100 --sampler ddpm \
        --steps 0 --resolution 32 --out DIR
    python3 suitcases.py DATA_DIR DIR [DIR ...]

Per directory: mean part count, samples with a thin part (half-extent x < 0.03 m: the handle),
the x distance between the centres of the two largest shells (half-extent x >= 0.03 m; the data
keeps them side by side), and the largest box IoU between two parts of a sample (medians).
"""
import glob, json, statistics as st, sys

def box_iou(a, b):
    inter = va = vb = 1.0
    for k in range(3):
        lo = max(a['center'][k] - a['half_extents'][k], b['center'][k] - b['half_extents'][k])
        hi = min(a['center'][k] + a['half_extents'][k], b['center'][k] + b['half_extents'][k])
        inter *= max(0.0, hi - lo)
        va *= 2 * a['half_extents'][k]
        vb *= 2 * b['half_extents'][k]
    return inter / (va + vb - inter)

def row(objs):
    parts, thin, sep, iou = [], 0, [], []
    for o in objs:
        ps = o['parts']
        parts.append(len(ps))
        thin += any(p['half_extents'][0] < 0.03 for p in ps)
        big = sorted((p for p in ps if p['half_extents'][0] >= 0.03),
                     key=lambda p: -p['half_extents'][0] * p['half_extents'][1] * p['half_extents'][2])
        if len(big) >= 2:
            sep.append(abs(big[0]['center'][0] - big[1]['center'][0]))
        iou.append(max((box_iou(ps[i], ps[j]) for i in range(len(ps)) for j in range(i + 1, len(ps))), default=0.0))
    return '%d objects | parts %.2f | handle %d | shell x-distance median %.3f | max box IoU median %.2f' % (
        len(objs), st.mean(parts), thin, st.median(sep), st.median(iou))

data = sys.argv[1]
index = json.load(open(data + '/dataset.json'))
test = [json.load(open('%s/objects/%s/object.json' % (data, o['id']))) for o in index['objects']
        if o['category'] == 'Suitcase' and o['split'] == 'test']
print('test split |', row(test))
for d in sys.argv[2:]:
    print(d, '|', row([json.load(open(f)) for f in sorted(glob.glob(d + '/sample_*/object.json'))]))
