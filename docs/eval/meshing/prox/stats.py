"""Fitted codes of the 921-part subset against the 16-view mean they start from (sub_v16) and
the encoder's single-view codes (sub_v1, the codes lg2's denoiser learned): movement, spacing,
and the share of variance in the encoder codes' top principal directions."""
import json, sys, numpy as np
def load(d):
    keys = json.load(open(f"{d}/codebook.json"))["keys"]
    raw = open(f"{d}/codebook.npy", "rb").read()
    h = int.from_bytes(raw[8:10], "little")
    return keys, np.frombuffer(raw[10 + h:], dtype="<f4").reshape(len(keys), -1).astype(np.float64)
keys, v1 = load('sub_v1'); _, v16 = load('sub_v16')
tr = np.array([k['split'] == 'train' for k in keys])
mu = v1[tr].mean(0)
_, _, vt = np.linalg.svd(v1[tr] - mu, full_matrices=False)
def nn(t):
    d = ((t[:, None] - t[None]) ** 2).sum(-1); np.fill_diagonal(d, np.inf); return np.sqrt(d.min(1))
def row(name, c):
    t = c[tr]; x = t - mu
    tot = (x ** 2).sum(); top = ((x @ vt[:16].T) ** 2).sum()
    print(f"{name:10s} move from 16-view mean: median {np.median(np.linalg.norm(c - v16, axis=1)):.3f} | "
          f"train nn spacing median {np.median(nn(t)):.3f} | outside the encoder's top-16 directions {1 - top / tot:.4f}")
row('v1', v1); row('v16', v16)
for d in sys.argv[1:]:
    row(d, load(d)[1])
