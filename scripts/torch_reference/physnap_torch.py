"""An independent PyTorch implementation of physnap's two inference networks.

It reads the weights physnap ships (burn's safetensors: every Linear stored as `weight`
[d_in, d_out] and `bias` [d_out]) and evaluates them literally as NAP writes them: every
Linear over a concatenation is one matrix product over the concatenated features (physnap
evaluates the same function by row blocks), the edge features of every directed pair are
built densely, attention is one einsum. Used by `fixtures.py` (golden values for the Rust
parity test) and `bench.py` (speed beside physnap).

    Denoiser(tensors, config, fast=False)(v, e, t, category) -> (eps_v, eps_e)

`fast=True` evaluates the Linears over concatenations by row blocks of the same weights, as
physnap does (the per-node terms A v_i, B v_j and the time and slot encodings once per node or
sample instead of once per edge): the same function with about half the edge FLOPs, which is
what `bench.py` times so that both sides do the same work.
    Decoder(tensors, pe_freqs)(q, features) -> sdf
"""

import json
import math

import numpy as np
import torch
import torch.nn.functional as F
from safetensors.numpy import load_file

K = 8
NODE_DIM = 135
EDGE_DIM = 13
NUM_EDGES = 28
TIME_STEPS = 1000
NODE_SLICES = [(0, 1), (1, 3), (4, 3), (7, 128)]
EDGE_SLICES = [(0, 3), (3, 6), (9, 4)]
PAIRS = [(i, j) for i in range(K) for j in range(i + 1, K)]


def sinusoidal_table(rows, dim):
    """Row n, columns 2k / 2k+1 = sin / cos(n · 10000^(−4k/d)), in f64 then f32."""
    n = np.arange(rows, dtype=np.float64)[:, None]
    k = np.arange(dim // 2, dtype=np.float64)[None, :]
    a = n * 10000.0 ** (-4.0 * k / dim)
    out = np.zeros((rows, dim))
    out[:, 0::2] = np.sin(a)
    out[:, 1::2] = np.cos(a)
    return torch.from_numpy(out.astype(np.float32))


def load_tensors(path):
    return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in load_file(path).items()}


def load_config(manifest_or_config, key="denoiser"):
    with open(manifest_or_config) as f:
        doc = json.load(f)
    return doc[key]["config"] if key in doc else doc


class Denoiser:
    def __init__(self, tensors, config, fast=False):
        self.fast = fast
        self.p = tensors
        self.c = config
        self.w = config["width"]
        self.heads = self.w // config["head_channels"]
        self.scale = 1.0 / math.sqrt(config["head_channels"] * 3)
        self.time_pe = sinusoidal_table(TIME_STEPS, config["t_pe_dim"])
        self.slot_pe = sinusoidal_table(K, config["slot_pe_dim"])
        dense = []
        for i in range(K):
            for j in range(K):
                if i < j:
                    dense.append(PAIRS.index((i, j)))
                elif i == j:
                    dense.append(NUM_EDGES)
                else:
                    dense.append(NUM_EDGES + 1 + PAIRS.index((j, i)))
        self.dense = torch.tensor(dense)
        self.upper = torch.tensor([i * K + j for i, j in PAIRS])
        swap = list(range(EDGE_DIM))
        swap[1], swap[2] = 2, 1
        self.swap = torch.tensor(swap)
        self.layers = config["layers"]

    def lin(self, name, x):
        y = x @ self.p[name + ".weight"]
        b = self.p.get(name + ".bias")
        return y if b is None else y + b

    def mlp(self, name, z, hidden):
        acts, h = [z], z
        for k in range(hidden):
            h = F.leaky_relu(self.lin(f"{name}.hidden.{k}", h), 0.01)
            acts.append(h)
        return self.lin(f"{name}.out", torch.cat(acts, -1))

    def rows(self, name, start, stop):
        return self.p[name + ".weight"][start:stop]

    def layer(self, l, h, g, tau):
        if self.fast:
            return self.layer_fast(l, h, g, tau)
        b, w, H = h.shape[0], self.w, self.heads
        hc = w // H
        name = f"layers.{l}"
        slot = self.slot_pe[None].expand(b, K, -1)
        vb = F.silu(self.lin(name + ".node_bind", torch.cat([h, slot, tau[:, None].expand(b, K, -1)], -1)))
        eb = F.silu(self.lin(name + ".edge_bind", torch.cat([g, tau[:, None].expand(b, K * K, -1)], -1)))
        vi = vb[:, :, None].expand(b, K, K, w)
        vj = vb[:, None].expand(b, K, K, w)
        z = torch.cat([vi, vj, eb.reshape(b, K, K, w)], -1)
        u = self.lin(name + ".edge_mlp2", F.silu(self.lin(name + ".edge_mlp1", z))).reshape(b, K * K, w)
        q = self.lin(name + ".query", vb).reshape(b, K, H, hc).transpose(1, 2)
        k = self.lin(name + ".key", vb).reshape(b, K, H, hc).transpose(1, 2)
        alpha = torch.softmax(q @ k.transpose(-1, -2) * self.scale, -1)  # [b, H, i, j]
        msg = torch.einsum("bhij,bijhc->bihc", alpha, u.reshape(b, K, K, H, hc)).reshape(b, K, w)
        v1 = msg + F.silu(self.lin(name + ".self_term", vb))
        pooled = v1.max(1, keepdim=True).values.expand(b, K, w)
        v2 = F.silu(self.lin(name + ".node_out", torch.cat([v1, pooled], -1)))
        return v2, u

    def layer_fast(self, l, h, g, tau):
        b, w, H = h.shape[0], self.w, self.heads
        hc, p = w // H, self.slot_pe.shape[1]
        name = f"layers.{l}"
        nb, eb_, m1, no = (name + x for x in (".node_bind", ".edge_bind", ".edge_mlp1", ".node_out"))
        time_n = tau @ self.rows(nb, w + p, None) + self.p[nb + ".bias"]
        vb = F.silu(h @ self.rows(nb, 0, w) + (self.slot_pe @ self.rows(nb, w, w + p))[None] + time_n[:, None])
        time_e = tau @ self.rows(eb_, w, None) + self.p[eb_ + ".bias"]
        eb = F.silu(g @ self.rows(eb_, 0, w) + time_e[:, None])
        a = vb @ self.rows(m1, 0, w)
        bj = vb @ self.rows(m1, w, 2 * w)
        c = (eb @ self.rows(m1, 2 * w, None) + self.p[m1 + ".bias"]).reshape(b, K, K, w)
        u = self.lin(name + ".edge_mlp2", F.silu(c + a[:, :, None] + bj[:, None])).reshape(b, K * K, w)
        q = self.lin(name + ".query", vb).reshape(b, K, H, hc).transpose(1, 2)
        k = self.lin(name + ".key", vb).reshape(b, K, H, hc).transpose(1, 2)
        alpha = torch.softmax(q @ k.transpose(-1, -2) * self.scale, -1)
        msg = torch.einsum("bhij,bijhc->bihc", alpha, u.reshape(b, K, K, H, hc)).reshape(b, K, w)
        v1 = msg + F.silu(self.lin(name + ".self_term", vb))
        pooled = v1.max(1, keepdim=True).values @ self.rows(no, w, None) + self.p[no + ".bias"]
        return F.silu(v1 @ self.rows(no, 0, w) + pooled), u

    def __call__(self, v, e, t, category=None):
        """v [B,8,135], e [B,28,13], t [B] long, category [B] long (categories = none) or None."""
        b = v.shape[0]
        cats = self.c["categories"]
        h = sum(self.lin(f"node_embed.{k}", v[..., o:o + n]) for k, (o, n) in enumerate(NODE_SLICES))
        full = torch.cat([e, torch.zeros(b, 1, EDGE_DIM, dtype=e.dtype), e[..., self.swap]], 1)
        dense = full[:, self.dense]
        if self.c["legacy_edge_embedding"]:
            line, rng = dense[..., 6:12], dense[..., 6:10]
        else:
            line, rng = dense[..., 3:9], dense[..., 9:13]
        g = (self.lin("edge_embed_class", dense[..., 0:3]) + self.lin("edge_embed_line", line)
             + self.lin("edge_embed_range", rng))
        idx = None
        if cats > 0:
            idx = category if category is not None else torch.full((b,), cats, dtype=torch.long)
            c = self.p["category.weight"][idx][:, None]
            h, g = h + c, g + c
        tau = self.time_pe[t]
        hs, gs = [h], [g[:, self.upper]]
        layered = "category_layers.weight" in self.p and idx is not None
        for l in range(self.layers):
            if layered:
                cl = self.p["category_layers.weight"][idx][:, None, l * self.w:(l + 1) * self.w]
                h, g = h + cl, g + cl
            h, g = self.layer(l, h, g, tau)
            hs.append(h)
            gs.append(g[:, self.upper])
        hw = self.lin("node_wide", torch.cat(hs, -1))
        gw = self.lin("edge_wide", torch.cat(gs, -1))
        nh, eh = len(self.c["node_head_hidden"]), len(self.c["edge_head_hidden"])
        eps_v = torch.cat([self.mlp(f"node_heads.{k}", torch.cat([hw, v[..., o:o + n]], -1), nh)
                           for k, (o, n) in enumerate(NODE_SLICES)], -1)
        eps_e = torch.cat([self.mlp(f"edge_heads.{k}", torch.cat([gw, e[..., o:o + n]], -1), eh)
                           for k, (o, n) in enumerate(EDGE_SLICES)], -1)
        return eps_v, eps_e


class Decoder:
    """The SDF decoder: f(q; features) with features = z W_c + b_c per point."""

    def __init__(self, tensors, pe_freqs, prefix="decoder."):
        self.p = {k[len(prefix):]: v for k, v in tensors.items() if k.startswith(prefix)}
        self.freqs = torch.tensor([float(2 ** f) for f in range(pe_freqs)])
        self.blocks = len({k.split(".")[1] for k in self.p if k.startswith("blocks.")})

    def lin(self, name, x):
        y = x @ self.p[name + ".weight"]
        b = self.p.get(name + ".bias")
        return y if b is None else y + b

    def code_features(self, codes):
        return self.lin("fc_c", codes)

    def __call__(self, q, features):
        m = q.shape[0]
        scaled = (q[:, :, None] * self.freqs).reshape(m, -1)
        pe = torch.cat([q, torch.cos(scaled), torch.sin(scaled)], 1)
        h = self.lin("fc_p", pe) + features
        for l in range(self.blocks):
            dx = self.lin(f"blocks.{l}.fc_1", F.relu(self.lin(f"blocks.{l}.fc_0", F.relu(h))))
            h = h + dx
        return self.lin("fc_out", F.leaky_relu(h, 0.2))[:, 0]
