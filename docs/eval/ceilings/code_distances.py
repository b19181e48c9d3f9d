"""How far generated shape codes sit from the training codes (session 45).

Usage: python3 code_distances.py CODES_DIR SAMPLE_DIR...   (needs numpy)

CODES_DIR is a `physnap train encode` output (codebook.json + codebook.npy: every part of the
data set encoded, with its split). Prints the median Euclidean distance from a code to its
nearest *training* code for: training codes (leave one out, 800 of them), the held-out test
parts' codes, and the latent parts of every `SAMPLE_DIR/sample_*/object.json` (a `physnap
generate --out` directory).
"""
import glob
import json
import sys

import numpy as np

codes_dir, samples = sys.argv[1], sys.argv[2:]
keys = json.load(open(f"{codes_dir}/codebook.json"))["keys"]
raw = open(f"{codes_dir}/codebook.npy", "rb").read()
header_len = int.from_bytes(raw[8:10], "little")
codes = np.frombuffer(raw[10 + header_len:], dtype="<f4").reshape(len(keys), -1).astype(np.float64)
split = np.array([k["split"] for k in keys])
train, test = codes[split == "train"], codes[split == "test"]


def nearest(x, loo=False):
    out = []
    for i in range(0, len(x), 256):
        d = ((x[i:i + 256, None, :] - train[None, :, :]) ** 2).sum(-1)
        if loo:
            for r in range(d.shape[0]):
                d[r, i + r] = np.inf
        out.append(np.sqrt(d.min(1)))
    return np.concatenate(out)


print(f"train {len(train)} codes, test {len(test)} codes")
print(f"train -> other train codes: median {np.median(nearest(train[:800], loo=True)):.3f}")
print(f"test -> train: median {np.median(nearest(test)):.3f}")
for d in samples:
    gen = np.array([
        q["shape"]["code"]
        for p in sorted(glob.glob(f"{d}/sample_*/object.json"))
        for q in json.load(open(p))["parts"]
        if q["shape"].get("type") == "latent"
    ])
    print(f"{d}: {len(gen)} generated codes -> train: median {np.median(nearest(gen)):.3f}")
