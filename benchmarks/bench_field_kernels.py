"""Benchmark: the SDF network's small C++ kernels against their PyTorch twins, at a training step's size.

Times, per call (median of ``--repeat``, wall clock, ``--threads`` threads), for P points:
  * the positional encoding (``SDFNetwork.encode`` vs ``encode_reference``; 6 frequencies -> (P, 39));
  * the chain rule of the encoding, forward and backward (``pe_chain`` vs ``pe_chain_reference``);
  * softplus(beta=100) with its slope, forward and backward (``_softplus_and_slope`` fast vs reference), on
    pre-activations around the knee (z ~ N(0, 0.05^2)) and large ones (z ~ N(0, 2^2): |100 z| > 87 on 66 % of the
    values, where an unfloored ``expf`` underflows and libmvec took its scalar path: 16.1 ms without the
    floor, 1.3 ms after, forward, 1 thread).

P defaults to 34304, the points of one default step (512 rays x 64 samples + 1536 eikonal points).

Usage:
    .venv/bin/python benchmarks/bench_field_kernels.py [--points 34304] [--threads 1] [--repeat 50]
"""

from __future__ import annotations

import argparse

import torch

from bench.microbench import median_seconds
from methods.monosdf.field import SDFNetwork, _softplus_and_slope
from methods.monosdf.grid import fast_available


def summed(outputs: tuple[torch.Tensor, torch.Tensor]) -> torch.Tensor:
    """A scalar depending on both outputs (both backward inputs are used)."""
    return outputs[0].sum() + outputs[1].sum()


def main() -> None:
    from bench.mkl_dispatch import reexec_with_mkl_shim

    reexec_with_mkl_shim()
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=34304)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=50)
    args = ap.parse_args()
    if not fast_available():
        raise SystemExit("no C++ compiler: the kernels are unavailable")
    torch.set_num_threads(args.threads)
    P, r = args.points, args.repeat
    net = SDFNetwork(None, hidden=64, layers=2, pe_frequencies=6, fast_grid=True)  # only its encoding is used
    u = torch.rand(P, 3) * 2 - 1
    pe = net.encode(u)
    gin = torch.randn(P, pe.shape[1], requires_grad=True)
    z = (torch.randn(P, 32) * 0.05).requires_grad_()  # pre-activations around the softplus knee
    z_large = torch.randn(P, 32) * 2.0  # a sharp, trained layer: most lanes far from the knee
    rows = [
        ("positional encoding", lambda: net.encode(u), lambda: net.encode_reference(u)),
        ("encoding chain rule, forward", lambda: net.pe_chain(gin, pe), lambda: net.pe_chain_reference(gin, pe)),
        ("encoding chain rule, fwd + bwd", lambda: net.pe_chain(gin, pe).sum().backward(),
         lambda: net.pe_chain_reference(gin, pe).sum().backward()),
        ("softplus + slope, forward", lambda: _softplus_and_slope(z, True), lambda: _softplus_and_slope(z, False)),
        ("softplus + slope, fwd + bwd", lambda: summed(_softplus_and_slope(z, True)).backward(),
         lambda: summed(_softplus_and_slope(z, False)).backward()),
        ("softplus + slope, fwd, large z", lambda: _softplus_and_slope(z_large, True), lambda: _softplus_and_slope(z_large, False)),
    ]
    print(f"{P} points, {args.threads} thread(s), median of {r} calls")
    for name, fast, ref in rows:
        f, s = 1000 * median_seconds(fast, r), 1000 * median_seconds(ref, r)
        print(f"  {name:32s} C++ {f:7.3f} ms   PyTorch twin {s:7.3f} ms   ({s / f:4.1f}x)")


if __name__ == "__main__":
    main()
