"""Benchmark: cost per sample of MonoSDF-style SDF MLPs without the grid (the MLP variant the MonoInstance
release trains, and CPU-scaled versions of it), for planning (docs/studies/monosdf-mlp-variant.md).

Proxy of the training step's SDF part: positional encoding (6 frequencies) -> MLP (softplus, beta 100,
optional skip connection re-injecting the input / sqrt 2) -> SDF + geometry feature; the gradient with
respect to x by autograd with ``create_graph`` (the eikonal term), and the backward of SDF + eikonal +
feature terms. Prints microseconds and samples per second per configuration.

Usage:
    .venv/bin/python benchmarks/bench_mlp_variant_cost.py [--points 8192] [--threads 1] [--repeats 4]
"""

from __future__ import annotations

import argparse
import time

import torch
import torch.nn.functional as F

CONFIGS = [(256, 8, (4,)), (128, 8, (4,)), (128, 4, (2,)), (64, 4, (2,)), (32, 2, ())]  # (hidden, layers, skip layers)


def encode(x: torch.Tensor, frequencies: int = 6) -> torch.Tensor:
    """(P, 3) -> (P, 3 + 6 F): [x, sin(2^k x), cos(2^k x)]."""
    f = 2.0 ** torch.arange(frequencies, dtype=x.dtype)
    fx = x[:, None, :] * f[None, :, None]
    return torch.cat([x, torch.sin(fx).flatten(1), torch.cos(fx).flatten(1)], dim=-1)


def build(in_dim: int, hidden: int, layers: int, skip: tuple[int, ...], geo: int) -> torch.nn.ModuleList:
    """Linear layers of an IDR / MonoSDF ImplicitNetwork: the layer before a skip outputs hidden - in_dim."""
    dims = [in_dim] + [hidden] * layers + [1 + geo]
    return torch.nn.ModuleList(
        torch.nn.Linear(dims[i], dims[i + 1] - in_dim if (i + 1) in skip else dims[i + 1]) for i in range(len(dims) - 1))


def forward(lins: torch.nn.ModuleList, x: torch.Tensor, skip: tuple[int, ...]) -> torch.Tensor:
    inp = encode(x)
    a = inp
    for i, lin in enumerate(lins[:-1]):
        if i in skip:
            a = torch.cat([a, inp], dim=-1) / 2**0.5
        a = F.softplus(lin(a), beta=100)
    return lins[-1](a)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=8192)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeats", type=int, default=4)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    x0 = torch.rand(args.points, 3) * 2 - 1
    base = None
    for hidden, layers, skip in CONFIGS:
        lins = build(3 + 6 * 6, hidden, layers, skip, geo=256 if hidden == 256 else 15)
        times = []
        for _ in range(args.repeats):
            t = time.perf_counter()
            x = x0.clone().requires_grad_(True)
            out = forward(lins, x, skip)
            grad = torch.autograd.grad(out[:, 0].sum(), x, create_graph=True)[0]
            loss = out[:, 0].abs().mean() + ((grad.norm(dim=-1) - 1) ** 2).mean() + out[:, 1:].pow(2).mean()
            loss.backward()
            times.append(time.perf_counter() - t)
        per = min(times[1:] or times) / args.points
        base = per if (hidden, layers) == (32, 2) else base
        print(f"MLP {layers} x {hidden}, skip {list(skip)}: {per * 1e6:7.2f} us/sample, {1 / per / 1e3:6.0f} k samples/s "
              f"({args.threads} thread(s))")
    if base:
        print("(ratios to the 2 x 32 MLP: divide the us/sample figures by its own)")


if __name__ == "__main__":
    main()
