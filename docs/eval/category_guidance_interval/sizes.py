"""Mean rest-pose size (box around all parts) and part count per category of `generate`
outputs in ROOT/<Category>/sample_*/object.json, against the training split.
Usage: python3 sizes.py ROOT"""
import json, os, sys, glob
root = sys.argv[1]
# The training split's column of the earlier table (same data, same definition).
md = open(os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', 'category_guidance_realism', 'sizes_and_parts.md')).read().splitlines()
train = {}
for l in md[2:]:
    if not l.startswith('| ') : continue
    c = [x.strip() for x in l.strip('|').split('|')]
    if len(c) < 2 or ' × ' not in c[1]: continue
    dims, parts = c[1].split(',')
    train[c[0]] = ([float(x) for x in dims.split(' × ')], float(parts))
ratios = []; parts_all = []
print('| category | training: size, parts | generated: size, parts |')
for cat in sorted(os.listdir(root)):
    objs = sorted(glob.glob(f'{root}/{cat}/*/object.json'))
    if not objs: continue
    sizes = []; np_ = []
    for o in objs:
        d = json.load(open(o))
        lo = [min(p['center'][i]-p['half_extents'][i] for p in d['parts']) for i in range(3)]
        hi = [max(p['center'][i]+p['half_extents'][i] for p in d['parts']) for i in range(3)]
        sizes.append([h-l for h,l in zip(hi,lo)]); np_.append(len(d['parts']))
    m = [sum(s[i] for s in sizes)/len(sizes) for i in range(3)]
    n = sum(np_)/len(np_)
    t = train.get(cat)
    ratios.append(max(m)/max(t[0])); parts_all.append(n)
    print(f"| {cat} | {' × '.join('%.2f'%x for x in t[0])}, {t[1]:.1f} | {' × '.join('%.2f'%x for x in m)}, {n:.1f} |")
print(f"largest extent generated/training, mean over categories: {sum(ratios)/len(ratios):.2f}; parts per sample, mean over categories: {sum(parts_all)/len(parts_all):.2f}")
