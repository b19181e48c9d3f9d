"""Meshes of generated parts against their boxes, per generate output directory: parts per
sample, mesh extent / box extent per axis (sorted), enclosed volume / box volume, connected
components of each part's mesh (vertices welded at 1 um). Session 48, docs/eval/layout_gain/decoders.
    python3 stats.py DIR..."""
import json, glob, sys, os
import numpy as np
def load(p):
    V=[];F=[]
    for l in open(p):
        if l.startswith('v '): V.append([float(x) for x in l.split()[1:4]])
        elif l.startswith('f '): F.append([int(x.split('/')[0])-1 for x in l.split()[1:4]])
    V=np.array(V); F=np.array(F,dtype=int)
    # vertices welded at 1 µm, for the connected components only
    _,inv=np.unique(np.round(V/1e-6).astype(np.int64),axis=0,return_inverse=True)
    return V, F, inv.reshape(-1)[F]
def comps(nv,F):
    par=list(range(nv))
    def f(a):
        while par[a]!=a: par[a]=par[par[a]]; a=par[a]
        return a
    for t in F:
        a=f(t[0])
        for b in t[1:]:
            b=f(b)
            if a!=b: par[b]=a
    return len({f(v) for t in F for v in t})
for d in sys.argv[1:]:
    ext=[];vol=[];nc=[];np_=[]
    for s in sorted(glob.glob(d+'/sample_*')):
        o=json.load(open(s+'/object.json')); np_.append(len(o['parts']))
        for i,p in enumerate(o['parts']):
            m=s+f'/meshes/part{i}.obj'
            if not os.path.exists(m): continue
            V,F,W=load(m)
            if len(F)==0: continue
            he=np.array(p['half_extents'])*2
            e=V.max(0)-V.min(0)
            ext.append(np.sort(e/he))
            a,b,c=V[F[:,0]],V[F[:,1]],V[F[:,2]]
            vol.append(abs(np.einsum('ij,ij->i',a,np.cross(b,c)).sum()/6)/np.prod(he))
            nc.append(comps(W.max()+1,W))
    ext=np.array(ext)
    print(f"{d}: parts/sample {np.mean(np_):.2f}, meshed parts {len(vol)}, mesh/box extent (min,mid,max axis) median {np.median(ext,0).round(2)}, volume/box median {np.median(vol):.2f} mean {np.mean(vol):.2f}, components mean {np.mean(nc):.2f}, >1 comp {np.mean(np.array(nc)>1):.2f}")
