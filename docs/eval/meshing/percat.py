"""Per-category hits of several eval generative reports, pooled per group.
Usage: python3 percat.py A1.json,A2.json B1.json,B2.json ...   (one comma-separated group a column)"""
import json,sys,collections
def load(files):
    hits=collections.Counter(); n=collections.Counter(); land=collections.defaultdict(collections.Counter)
    for f in files:
        d=json.load(open(f))
        for c in d['conditional']['categories']:
            hits[c['category']]+=c['hits']; n[c['category']]+=c['samples']
            for k,v in c['nearest'].items():
                if k!=c['category']: land[c['category']][k]+=v
    return hits,n,land
groups=[g.split(',') for g in sys.argv[1:]]
res=[load(g) for g in groups]
cats=sorted(res[0][1])
for c in cats:
    print(f"{c:18s}", "  ".join(f"{r[0][c]:2d}/{r[1][c]:2d} {dict(r[2][c])}" for r in res))
print("total", [sum(r[0].values()) for r in res],[sum(r[1].values()) for r in res])
