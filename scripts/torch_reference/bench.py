"""Time the shipped denoiser in PyTorch and in physnap the same way, alternating A B A B.

    cargo build --release --example bench_denoiser
    python scripts/torch_reference/bench.py [--weights weights] [--threads 2] [--rounds 3]
        [--physnap target/release/examples/bench_denoiser]

PyTorch runs the row-block form of the network (`fast=True`, physnap's rewrites; checked here
against the literal form). Each round measures PyTorch (eager, CPU, `torch.set_num_threads(threads)`) in this process,
then runs `bench_denoiser --versus` (physnap's host path, a rayon pool of `threads`) in a
fresh process; both take the median of the same repetition counts after two warm-up runs,
on Gaussian inputs of the same shapes. Quantities: forward B = 1 and B = 16, forward + input
gradient B = 1 (guidance's pattern: ∇ of Σ x̂₀·r through the network), and a 200-step DDIM
sample B = 1 with a category and no classifier-free guidance. Printed: the median over
rounds of each side, and torch ÷ physnap (> 1: physnap is faster). Not run in CI.
"""

import argparse
import json
import os
import statistics
import subprocess
import time

import numpy as np
import torch

import physnap_torch as pt


def median_ms(reps, f):
    f()
    f()
    times = []
    for _ in range(reps):
        t = time.perf_counter()
        f()
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def inputs(b, cats, seed=1):
    g = torch.Generator().manual_seed(seed)
    v = torch.randn(b, pt.K, pt.NODE_DIM, generator=g)
    e = torch.randn(b, pt.NUM_EDGES, pt.EDGE_DIM, generator=g)
    t = torch.tensor([(i * 61) % 1000 for i in range(b)])
    c = torch.tensor([i % 13 for i in range(b)]) if cats > 0 else None
    return v, e, t, c


def ddim_timesteps(total, steps):
    ts = sorted({round(k * (total - 1) / (steps - 1)) for k in range(steps)}, reverse=True)
    return ts


def torch_side(model, cats):
    out = {}
    with torch.no_grad():
        for b, reps, key in [(1, 101, "forward_b1"), (16, 21, "forward_b16")]:
            v, e, t, c = inputs(b, cats)
            out[key] = median_ms(reps, lambda: model(v, e, t, c))
    v, e, t, c = inputs(1, cats)
    rv, re, _, _ = inputs(1, cats, seed=2)
    s = r = 0.5 ** 0.5

    def fwd_grad():
        va, ea = v.clone().requires_grad_(), e.clone().requires_grad_()
        ev, ee = model(va, ea, t, c)
        loss = (((va - ev * s) / r) * rv).sum() + (((ea - ee * s) / r) * re).sum()
        loss.backward()
        return va.grad, ea.grad

    out["forward_grad_b1"] = median_ms(51, fwd_grad)
    betas = np.linspace(0.001, 0.02, 1000)
    abar = np.cumprod(1.0 - betas)
    ts = ddim_timesteps(1000, 200)
    cat = torch.tensor([6]) if cats > 0 else None

    def sample():
        g = torch.Generator().manual_seed(1)
        x_v = torch.randn(1, pt.K, pt.NODE_DIM, generator=g)
        x_e = torch.randn(1, pt.NUM_EDGES, pt.EDGE_DIM, generator=g)
        with torch.no_grad():
            for k, t in enumerate(ts):
                a = float(abar[t])
                a_prev = float(abar[ts[k + 1]]) if k + 1 < len(ts) else 1.0
                ev, ee = model(x_v, x_e, torch.tensor([t]), cat)
                c_eps = (1 - a_prev) ** 0.5 - (a_prev / a) ** 0.5 * (1 - a) ** 0.5
                x_v = x_v * (a_prev / a) ** 0.5 + ev * c_eps
                x_e = x_e * (a_prev / a) ** 0.5 + ee * c_eps
        return x_v, x_e

    out["sample_ddim200_b1"] = median_ms(7, sample)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--weights", default="weights")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--physnap", default="target/release/examples/bench_denoiser")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    cfg = pt.load_config(os.path.join(args.weights, "manifest.json"))
    tensors = pt.load_tensors(os.path.join(args.weights, "denoiser.safetensors"))
    model = pt.Denoiser(tensors, cfg, fast=True)
    # The timed form is the same function as the literal one the fixtures use.
    v, e, t, c = inputs(3, cfg["categories"])
    with torch.no_grad():
        a, b = model(v, e, t, c), pt.Denoiser(tensors, cfg)(v, e, t, c)
    err = max(float((x - y).abs().max() / y.abs().max()) for x, y in zip(a, b))
    assert err < 1e-5, f"row-block form differs from the literal one by {err:e}"
    env = dict(os.environ, RAYON_NUM_THREADS=str(args.threads))
    rounds = {"torch": [], "physnap": []}
    for k in range(args.rounds):
        rounds["torch"].append(torch_side(model, cfg["categories"]))
        run = subprocess.run([args.physnap, "--versus", "--weights", args.weights, "--threads", str(args.threads)],
                             check=True, capture_output=True, text=True, env=env)
        rounds["physnap"].append(json.loads(run.stdout.strip().splitlines()[-1]))
        print(f"round {k + 1}: torch {rounds['torch'][-1]}\n         physnap {rounds['physnap'][-1]}", flush=True)
    print(f"\ntorch {torch.__version__}, {args.threads} threads, median of {args.rounds} rounds (ms)\n")
    print("| quantity | PyTorch | physnap | torch ÷ physnap |")
    print("|---|---|---|---|")
    for key in rounds["torch"][0]:
        a = statistics.median(r[key] for r in rounds["torch"])
        b = statistics.median(r[key] for r in rounds["physnap"])
        print(f"| {key} | {a:.2f} | {b:.2f} | {a / b:.2f} |")


if __name__ == "__main__":
    main()
