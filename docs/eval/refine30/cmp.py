#!/usr/bin/env python3
"""Paired comparison of guided pc+pen+mob samples from slice dirs or merged JSONs, restricted to
the (cloud, seed) pairs all sources share. usage: cmp.py BLOCK LABEL=SRC ... (SRC: glob of slice
dirs or a merged json)."""
import glob, json, sys, statistics as st
block = sys.argv[1]
def load(src):
    out = {}
    files = [src] if src.endswith('.json') else [d + '/guided_table.json' for d in glob.glob(src)]
    for f in files:
        try: d = json.load(open(f))
        except FileNotFoundError: continue
        for row in d['rows']:
            if row['variant'] != 'pc+pen+mob' or row['category_aware'] != (block == 'yes'): continue
            for s in row['per_sample']:
                out[(s['cloud'], s['seed'])] = s
    return out
srcs = [(a.split('=', 1)[0], load(a.split('=', 1)[1])) for a in sys.argv[2:]]
keys = set.intersection(*(set(s) for _, s in srcs))
print(f'block {block}: {len(keys)} shared samples')
print('| metric | ' + ' | '.join(f'{l} mean / median / >1e-4' for l, _ in srcs) + ' |')
for m in ['e_pc', 'd_pc', 'e_pen', 'e_mob', 'o_mesh', 'id_gt', 'seconds']:
    cells = []
    for _, s in srcs:
        v = [s[k][m] for k in keys if s[k].get(m) is not None]
        if not v: cells.append('—'); continue
        cells.append(f'{st.mean(v):.3g} / {st.median(v):.2g} / {100*sum(x>1e-4 for x in v)/len(v):.0f} %')
    print(f'| {m} | ' + ' | '.join(cells) + ' |')
