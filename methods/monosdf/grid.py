"""Multi-resolution feature grid (MonoSDF's grid variant, scaled down for a CPU) with analytic spatial
Jacobians.

Levels ``l = 0..L-1`` have resolutions ``res_l = floor(base * b^l)`` (geometric growth from
``base_resolution`` to ``max_resolution``). A level whose ``(res + 1)^3`` vertices fit in the table
size ``2^log2_table`` is stored densely (no collisions); finer levels are hashed into ``2^log2_table``
entries with instant-NGP's spatial hash. Every level stores ``features_per_level`` features per vertex.

Inputs are points in the cube ``[-1, 1]^3`` (the caller divides by the bounding-sphere radius); each
level interpolates trilinearly. Besides the features, :func:`interpolate` returns their spatial
Jacobian ``d feat / d x`` (analytic: the derivative of the trilinear weights), which the SDF network
propagates forward to get SDF gradients without double backward (see ``field.py``).

Two implementations with one contract (tests compare them):

* ``interpolate_reference``: plain PyTorch gathers; autograd gives the table gradient. Obviously correct.
* ``interpolate_fast``: a C++/OpenMP kernel (``_grid_kernel.cpp``, compiled on first use with
  ``torch.utils.cpp_extension.load`` in a build folder keyed by its sources and flags, ``methods.cpp_build``) with a hand-written
  backward (scatter-add into the table). Falls back to the reference when no compiler is available.
"""

from __future__ import annotations

import contextlib
import math
from dataclasses import dataclass
from typing import Iterator

import torch

from methods.cpp_build import CppExtension, build_lock  # noqa: F401  (build_lock: re-exported for the tests)

PRIMES = (1, 2654435761, 805459861)


@dataclass(frozen=True)
class GridSpec:
    """Static layout of the grid.

    Attributes:
        resolutions: per-level resolution (cells per axis).
        offsets: per-level first row in the table; ``offsets[-1]`` is the total number of rows.
        hashed: per-level flag, True if the level is hashed (else dense).
        features: features per level.
    """

    resolutions: tuple[int, ...]
    offsets: tuple[int, ...]
    hashed: tuple[bool, ...]
    features: int

    @property
    def levels(self) -> int:
        return len(self.resolutions)

    @property
    def out_dim(self) -> int:
        return self.levels * self.features

    @property
    def rows(self) -> int:
        return self.offsets[-1]

    def meta_tensor(self) -> torch.Tensor:
        """(L, 4) int64: resolution, offset, size, hashed."""
        rows = [[r, self.offsets[i], self.offsets[i + 1] - self.offsets[i], int(h)] for i, (r, h) in enumerate(zip(self.resolutions, self.hashed))]
        return torch.tensor(rows, dtype=torch.int64)


def make_grid_spec(levels: int, features_per_level: int, log2_table: int, base_resolution: int, max_resolution: int) -> GridSpec:
    """Build the level layout (see module docstring)."""
    if levels < 1 or base_resolution < 2 or max_resolution < base_resolution:
        raise ValueError(f"bad grid spec: levels={levels}, base={base_resolution}, max={max_resolution}")
    growth = math.exp((math.log(max_resolution) - math.log(base_resolution)) / max(levels - 1, 1))
    table = 2**log2_table
    res, offs, hashed = [], [0], []
    for lvl in range(levels):
        r = int(math.floor(base_resolution * growth**lvl + 1e-6))
        dense = (r + 1) ** 3
        size = dense if dense <= table else table
        res.append(r)
        hashed.append(dense > table)
        offs.append(offs[-1] + size)
    return GridSpec(tuple(res), tuple(offs), tuple(hashed), features_per_level)


def _corner_index(v: torch.Tensor, res: int, size: int, hashed: bool) -> torch.Tensor:
    """Row index (within a level) of integer vertex coordinates v (..., 3) int64."""
    if hashed:
        h = (v[..., 0] * PRIMES[0]) ^ (v[..., 1] * PRIMES[1]) ^ (v[..., 2] * PRIMES[2])
        return h & (size - 1)
    n = res + 1
    return v[..., 0] + n * (v[..., 1] + n * v[..., 2])


def interpolate_reference(table: torch.Tensor, x: torch.Tensor, spec: GridSpec, with_jacobian: bool = True) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Trilinear interpolation of every level, in plain PyTorch.

    Args:
        table: (rows, F) float32 parameters.
        x: (P, 3) points in [-1, 1]^3 (clamped).
        spec: grid layout.
        with_jacobian: also return d feat / d x.

    Returns:
        feat (P, L*F), jac (P, 3, L*F) (d feat_j / d x_i at [p, i, j]) or None.
    """
    P = x.shape[0]
    u = ((x.clamp(-1.0, 1.0) + 1.0) * 0.5).to(table.dtype)
    corners = torch.tensor([[i, j, k] for k in (0, 1) for j in (0, 1) for i in (0, 1)], dtype=torch.int64)  # (8, 3)
    feats, jacs = [], []
    for lvl, res in enumerate(spec.resolutions):
        pos = u * res
        i0 = torch.clamp(torch.floor(pos), 0, res - 1)
        f = pos - i0  # (P, 3)
        i0 = i0.long()
        verts = i0[:, None, :] + corners[None]  # (P, 8, 3)
        size = spec.offsets[lvl + 1] - spec.offsets[lvl]
        idx = _corner_index(verts, res, size, spec.hashed[lvl]) + spec.offsets[lvl]  # (P, 8)
        vals = table[idx.reshape(-1)].reshape(P, 8, spec.features)  # (P, 8, F)
        c = corners[None].to(table.dtype)  # (1, 8, 3)
        wd = c * f[:, None, :] + (1 - c) * (1 - f[:, None, :])  # (P, 8, 3) per-axis weights
        w = wd.prod(-1)  # (P, 8)
        feats.append((w[..., None] * vals).sum(1))
        if with_jacobian:
            sign = 2 * c - 1  # d wd / d f
            dw = torch.stack([sign[..., 0] * wd[..., 1] * wd[..., 2], wd[..., 0] * sign[..., 1] * wd[..., 2], wd[..., 0] * wd[..., 1] * sign[..., 2]], -1)
            dw = dw * (0.5 * res)  # d f / d x = res / 2
            jacs.append(torch.einsum("pcd,pcf->pdf", dw, vals))
    feat = torch.cat(feats, -1)
    jac = torch.cat(jacs, -1) if with_jacobian else None
    return feat, jac


# ----------------------------------------------------------------------------- fast path
EXT_NAME = "monosdf_grid_kernel"
_KERNEL = CppExtension(EXT_NAME, __file__, ("_grid_kernel.cpp", "_encoding_kernel.cpp", "_float_mode.cpp"),
                       cflags=("-O3", "-fopenmp", "-march=native", "-ffast-math"), ldflags=("-fopenmp",))


def _load_extension():
    """Compile (first use) and load the C++ kernel; None if no compiler is available."""
    return _KERNEL.load()


class _GridFunction(torch.autograd.Function):
    @staticmethod
    def forward(ctx, table: torch.Tensor, x: torch.Tensor, meta: torch.Tensor, features: int, with_jacobian: bool):  # type: ignore[override]
        ext = _load_extension()
        feat, jac = ext.forward(table.contiguous(), x.contiguous(), meta, features, with_jacobian)
        ctx.save_for_backward(x, meta)
        ctx.rows = table.shape[0]
        ctx.features = features
        ctx.with_jacobian = with_jacobian
        return feat, jac

    @staticmethod
    def backward(ctx, grad_feat: torch.Tensor, grad_jac: torch.Tensor):  # type: ignore[override]
        x, meta = ctx.saved_tensors
        ext = _load_extension()
        if grad_feat is None:
            grad_feat = torch.zeros(0)
        if grad_jac is None or not ctx.with_jacobian:
            grad_jac = torch.zeros(0)
        grad_table = ext.backward(grad_feat.contiguous(), grad_jac.contiguous(), x.contiguous(), meta, ctx.rows, ctx.features)
        return grad_table, None, None, None, None


class _JacobianContract(torch.autograd.Function):
    @staticmethod
    def forward(ctx, jac: torch.Tensor, g: torch.Tensor):  # type: ignore[override]
        jac, g = jac.contiguous(), g.contiguous()
        ctx.save_for_backward(jac, g)
        return _load_extension().jacobian_contract_forward(jac, g)

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):  # type: ignore[override]
        jac, g = ctx.saved_tensors
        grad_jac, grad_g = _load_extension().jacobian_contract_backward(jac, g, grad_out.contiguous())
        return grad_jac, grad_g


def jacobian_contract_reference(jac: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    """``out[p, d] = sum_j jac[p, d, j] g[p, j]``: jac (P, 3, C), g (P, C) -> (P, 3). Plain PyTorch."""
    return (jac * g[:, None, :]).sum(-1)


def jacobian_contract(jac: torch.Tensor, g: torch.Tensor, fast: bool = True) -> torch.Tensor:
    """:func:`jacobian_contract_reference` through one C++ pass per direction (PyTorch's broadcast
    multiply + sum materialise (P, 3, C) products forward and backward: ~3.9 of a 32 ms step)."""
    if fast and jac.dtype == torch.float32 and g.dtype == torch.float32 and fast_available():
        return _JacobianContract.apply(jac, g)
    return jacobian_contract_reference(jac, g)


def fast_available() -> bool:
    """True if the C++ kernel compiled and loaded."""
    return _load_extension() is not None


def simd_kernel_compiled() -> bool:
    """True if the C++ kernel was built with its AVX-512 grid kernels (``-march=native`` on a CPU with AVX-512F)."""
    ext = _load_extension()
    return ext is not None and bool(ext.simd_kernel_compiled())


@contextlib.contextmanager
def per_point_grid_kernel() -> Iterator[None]:
    """Inside: the C++ kernel's per-point grid forward / backward (the twin of the AVX-512 ones, which are the
    default where compiled). Process-wide; for tests and benchmarks."""
    ext = _load_extension()
    if ext is None:
        yield
        return
    ext.set_simd_kernel(False)
    try:
        yield
    finally:
        ext.set_simd_kernel(True)


def interpolate_fast(table: torch.Tensor, x: torch.Tensor, spec: GridSpec, with_jacobian: bool = True) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Same contract as :func:`interpolate_reference`, through the C++ kernel (falls back if unavailable)."""
    if not fast_available() or table.dtype != torch.float32:
        return interpolate_reference(table, x, spec, with_jacobian)
    feat, jac = _GridFunction.apply(table, x.float(), spec.meta_tensor(), spec.features, with_jacobian)
    return feat, (jac if with_jacobian else None)


class FeatureGrid(torch.nn.Module):
    """The learnable multi-resolution grid. ``forward(x) -> (feat (P, L*F), jac (P, 3, L*F) | None)``."""

    def __init__(self, spec: GridSpec, init_scale: float = 1e-4, fast: bool = True, seed: int = 0) -> None:
        super().__init__()
        self.spec = spec
        self.fast = fast
        g = torch.Generator().manual_seed(seed)
        self.table = torch.nn.Parameter((torch.rand(spec.rows, spec.features, generator=g) * 2 - 1) * init_scale)

    def forward(self, x: torch.Tensor, with_jacobian: bool = True) -> tuple[torch.Tensor, torch.Tensor | None]:
        fn = interpolate_fast if self.fast else interpolate_reference
        return fn(self.table, x, self.spec, with_jacobian)
