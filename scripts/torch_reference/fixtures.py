"""Write the golden fixtures of `tests/torch_reference.rs` from the PyTorch reference.

    python scripts/torch_reference/fixtures.py [--weights weights] [--out tests/fixtures/torch_reference]

For two denoisers (a tiny random one, written here as `tiny_denoiser.safetensors` with its
`tiny_config.json`, and the shipped `weights/denoiser.safetensors`) and two cases each
("mixed": four samples at t = 0, 137, 500, 999 with three categories and "no category";
"none": two samples called without a category), it writes the inputs, ε̂ and the input
gradient of Σ ⟨r, ε̂⟩ for random r, and for the shipped SDF decoder the values and input
gradients at random points. Every array is 2-D float32 (`.npy`), the layout physnap's NPY
reader takes. Rerun after any change to the inference path or the shipped weights.
"""

import argparse
import json
import os

import numpy as np
import torch
from safetensors.numpy import save_file

import physnap_torch as pt

TINY = {
    "width": 32, "layers": 2, "head_channels": 8, "t_pe_dim": 16, "slot_pe_dim": 8,
    "node_head_hidden": [16, 12], "edge_head_hidden": [16], "categories": 5,
    "legacy_edge_embedding": False, "category_layers": True,
}


def tiny_weights(cfg, rng):
    """Random weights in burn's layout: U(±1/√fan_in) linears, N(0, 1) tables."""
    w, out = cfg["width"], {}

    def lin(name, d_in, d_out):
        bound = 1.0 / np.sqrt(d_in)
        out[name + ".weight"] = rng.uniform(-bound, bound, (d_in, d_out)).astype(np.float32)
        out[name + ".bias"] = rng.uniform(-bound, bound, (d_out,)).astype(np.float32)

    def mlp(name, d_in, hidden, d_out):
        d = d_in
        for k, h in enumerate(hidden):
            lin(f"{name}.hidden.{k}", d, h)
            d = h
        lin(f"{name}.out", d_in + sum(hidden), d_out)

    for k, (_, n) in enumerate(pt.NODE_SLICES):
        lin(f"node_embed.{k}", n, w)
    lin("edge_embed_class", 3, w)
    lin("edge_embed_line", 6, w)
    lin("edge_embed_range", 4, w)
    c = cfg["categories"] + 1
    out["category.weight"] = rng.normal(size=(c, w)).astype(np.float32)
    out["category_layers.weight"] = rng.normal(size=(c, cfg["layers"] * w)).astype(np.float32)
    p, t = cfg["slot_pe_dim"], cfg["t_pe_dim"]
    for l in range(cfg["layers"]):
        n = f"layers.{l}"
        lin(n + ".node_bind", w + p + t, w)
        lin(n + ".edge_bind", w + t, w)
        lin(n + ".edge_mlp1", 3 * w, w)
        for m in ("edge_mlp2", "query", "key", "self_term"):
            lin(f"{n}.{m}", w, w)
        lin(n + ".node_out", 2 * w, w)
    lin("node_wide", (cfg["layers"] + 1) * w, w)
    lin("edge_wide", (cfg["layers"] + 1) * w, w)
    for k, (_, n) in enumerate(pt.NODE_SLICES):
        mlp(f"node_heads.{k}", w + n, cfg["node_head_hidden"], n)
    for k, (_, n) in enumerate(pt.EDGE_SLICES):
        mlp(f"edge_heads.{k}", w + n, cfg["edge_head_hidden"], n)
    return out


def save(out, name, x):
    x = np.asarray(x, dtype=np.float32)
    np.save(os.path.join(out, name + ".npy"), x.reshape(x.shape[0], -1))


def denoiser_cases(model, cfg, prefix, out, rng):
    cats = cfg["categories"]
    cases = {
        "mixed": ([0, 137, 500, 999], [min(6, cats - 1), 0, cats - 1, cats]),
        "none": ([42, 800], None),
    }
    for case, (t, cat) in cases.items():
        b = len(t)
        v = torch.from_numpy(rng.normal(size=(b, pt.K, pt.NODE_DIM)).astype(np.float32)).requires_grad_()
        e = torch.from_numpy(rng.normal(size=(b, pt.NUM_EDGES, pt.EDGE_DIM)).astype(np.float32)).requires_grad_()
        rv = torch.from_numpy(rng.normal(size=(b, pt.K, pt.NODE_DIM)).astype(np.float32))
        re = torch.from_numpy(rng.normal(size=(b, pt.NUM_EDGES, pt.EDGE_DIM)).astype(np.float32))
        tt = torch.tensor(t)
        cc = None if cat is None else torch.tensor(cat)
        ev, ee = model(v, e, tt, cc)
        ((ev * rv).sum() + (ee * re).sum()).backward()
        base = f"{prefix}_{case}_"
        for name, x in [("v", v.detach()), ("e", e.detach()), ("t", tt[:, None]), ("eps_v", ev.detach()),
                        ("eps_e", ee.detach()), ("r_v", rv), ("r_e", re), ("grad_v", v.grad),
                        ("grad_e", e.grad)]:
            save(out, base + name, x.numpy())
        if cc is not None:
            save(out, base + "category", cc[:, None].numpy())


def decoder_case(weights, out, rng):
    with open(os.path.join(weights, "manifest.json")) as f:
        manifest = json.load(f)
    dec = pt.Decoder(pt.load_tensors(os.path.join(weights, manifest["shape_prior"]["file"])),
                     manifest["shape_prior"]["config"]["pe_freqs"])
    parts, n = 3, 96
    codes = torch.from_numpy(rng.normal(size=(parts, manifest["shape_prior"]["config"]["latent"])).astype(np.float32))
    features = dec.code_features(codes).detach()
    idx = torch.arange(n) % parts
    q = torch.from_numpy(rng.uniform(-0.6, 0.6, (n, 3)).astype(np.float32)).requires_grad_()
    rows = features[idx].clone().requires_grad_()
    f = dec(q, rows)
    f.sum().backward()
    for name, x in [("points", q.detach()), ("features", features), ("index", idx[:, None]),
                    ("sdf", f.detach()[:, None]), ("grad_points", q.grad), ("grad_features", rows.grad)]:
        save(out, "decoder_" + name, x.numpy())


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="weights")
    ap.add_argument("--out", default="tests/fixtures/torch_reference")
    args = ap.parse_args()
    os.makedirs(args.out, exist_ok=True)
    torch.manual_seed(0)
    rng = np.random.default_rng(20261202)

    tensors = tiny_weights(TINY, rng)
    save_file(tensors, os.path.join(args.out, "tiny_denoiser.safetensors"))
    with open(os.path.join(args.out, "tiny_config.json"), "w") as f:
        json.dump(TINY, f, indent=2)
        f.write("\n")
    tiny = pt.Denoiser({k: torch.from_numpy(v) for k, v in tensors.items()}, TINY)
    denoiser_cases(tiny, TINY, "tiny", args.out, rng)

    cfg = pt.load_config(os.path.join(args.weights, "manifest.json"))
    shipped = pt.Denoiser(pt.load_tensors(os.path.join(args.weights, "denoiser.safetensors")), cfg)
    denoiser_cases(shipped, cfg, "shipped", args.out, rng)
    decoder_case(args.weights, args.out, rng)
    print(f"fixtures written to {args.out}")


if __name__ == "__main__":
    main()
