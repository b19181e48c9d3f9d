"""Encoder codes (NAP's encoding, the ws10 cycle's codebook) against fc's fitted codes (16 views,
50 Adam steps on 512 samples): how far fitting moves a code, and how the two sets are spread."""
import json, numpy as np
def load(d):
    keys = json.load(open(f"{d}/codebook.json"))["keys"]
    raw = open(f"{d}/codebook.npy", "rb").read()
    h = int.from_bytes(raw[8:10], "little")
    c = np.frombuffer(raw[10 + h:], dtype="<f4").reshape(len(keys), -1).astype(np.float64)
    return keys, c
ka, a = load('/work/exp/s45/ws/cycle3_ws10')
kb, b = load('/work/exp/s46/codes_fit')
assert [k['split'] for k in ka] == [k['split'] for k in kb]
tr = np.array([k['split'] == 'train' for k in ka])
def nn(x, ref, loo):
    out = []
    for i in range(0, len(x), 256):
        d = ((x[i:i+256, None] - ref[None]) ** 2).sum(-1)
        if loo:
            for r in range(d.shape[0]): d[r, i + r] = np.inf
        out.append(np.sqrt(d.min(1)))
    return np.concatenate(out)
for name, c in (('encoder', a), ('fitted', b)):
    t = c[tr]
    print(f"{name:8s} norm median {np.median(np.linalg.norm(t, axis=1)):.3f}  per-channel std mean {t.std(0).mean():.3f}  "
          f"nn distance (800 train, loo) median {np.median(nn(t[:800], t, True)):.3f}")
d = np.linalg.norm(a - b, axis=1)
print(f"|fitted - encoder| median {np.median(d):.3f}, 90th pct {np.percentile(d, 90):.3f}")
# PCA spectrum: how much of the variance the first k components hold
for name, c in (('encoder', a[tr]), ('fitted', b[tr])):
    s = np.linalg.svd(c - c.mean(0), compute_uv=False) ** 2
    cs = np.cumsum(s) / s.sum()
    print(name, 'variance in first 8/16/32/64 components', [round(float(cs[k - 1]), 3) for k in (8, 16, 32, 64)])
