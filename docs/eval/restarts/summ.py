import json, sys
# Usage: summ.py FILE... : category accuracy, 1-NNA, MMD, COV, valid per eval generative JSON.
tot = {}
for f in sys.argv[1:]:
    d = json.load(open(f))
    c, u = d['conditional'], d['unconditional']
    hits = sum(x['hits'] for x in c['categories']); n = sum(x['samples'] for x in c['categories'])
    print(f"{f}: seed {d['seed']} acc {c['accuracy']:.3f} ({hits}/{n}) 1-NNA {u['one_nna']:.3f} MMD {u['mmd']:.4f} COV {u['cov']:.3f} valid {u['valid']}/{u['samples']}")
    for x in c['categories']:
        t = tot.setdefault(x['category'], [0, 0]); t[0] += x['hits']; t[1] += x['samples']
h = sum(v[0] for v in tot.values()); n = sum(v[1] for v in tot.values())
print(f"pooled {h}/{n} = {h/n:.3f}")
print(" ".join(f"{k}:{v[0]}/{v[1]}" for k, v in sorted(tot.items())))
