"""The SDF and colour networks (MonoSDF's grid variant, scaled down for a CPU).

SDF network: ``[grid features(x / R), PE(x)] -> Softplus(beta=100) MLP -> (sdf, geometry feature)``, with
``PE(x) = [x, sin(2^k x), cos(2^k x)]_{k < pe_frequencies}`` (MonoSDF's grid config: ``multires = 6``;
``pe_frequencies = 0`` feeds ``x`` alone). As MonoSDF's ``ImplicitNetworkGrid``: the MLP and the encoding
see the point in normalised units (``x``), only the grid sees it divided by the bounding-sphere radius
(MonoSDF's ``divide_factor``, which its configs set to the sphere: 1.0-1.5 for rooms, 5.0 for DTU), and the
SDF is the MLP output itself. For a room (R = 1) this is the same arithmetic as dividing everything by R;
for an object scene (R = 4) the earlier layout (MLP on ``x / R``, output times R) shrank the object 4x in
the MLP's coordinates and made every step of the MLP's weights move the SDF 4x as far (docs/monosdf.md,
"Object scenes").
Its spatial gradient (normals, eikonal term) is computed EXPLICITLY as differentiable tensor ops: the
grid returns ``d feat / d x`` analytically, and the MLP's vector-Jacobian product for its single SDF
output is written out layer by layer (``g <- (g * softplus'(z)) @ W``, softplus' = a sigmoid). The
gradient is then an ordinary differentiable tensor, so the eikonal and normal losses need only a
first-order backward (no double backward, which is slow on a CPU and unsupported by ``torch.compile``).
(Forward-mode propagation of the 3-column Jacobian was measured 3x slower: it pushes (P, 3, H) through
every layer instead of (P, H).) A slow twin,
:func:`sdf_gradient_autograd`, computes the same gradient with ``torch.autograd.grad`` for tests.

The SDF is clamped to the bounding sphere like MonoSDF: ``sdf = min(sdf, R - |x|)`` (indoor scenes, so
every ray ends inside the sphere); where the clamp is active the gradient is ``-x / |x|``.

Geometric initialisation (IDR / MonoSDF): the network starts as a sphere SDF of radius ``init_radius``
(``inside_out`` for rooms, where the cameras are inside the sphere: sdf > 0 inside).
"""

from __future__ import annotations

import math
from typing import cast

import torch
import torch.nn.functional as F

from methods.monosdf.grid import FeatureGrid, GridSpec, _load_extension, fast_available, jacobian_contract

SOFTPLUS_BETA = 100.0
_INV_SQRT2 = 1.0 / math.sqrt(2.0)


def softplus_and_slope_reference(z: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Softplus(beta=100) and its derivative sigmoid(beta z) (plain PyTorch twin of the fused kernel)."""
    return F.softplus(z, beta=SOFTPLUS_BETA), torch.sigmoid(SOFTPLUS_BETA * z)


class _SoftplusSlope(torch.autograd.Function):
    """Fused C++ softplus + slope with a fused backward (the MLP needs both outputs)."""

    @staticmethod
    def forward(ctx, z: torch.Tensor):  # type: ignore[override]
        a, s = _load_extension().softplus_slope_forward(z, SOFTPLUS_BETA)
        ctx.save_for_backward(s)
        return a, s

    @staticmethod
    def backward(ctx, grad_a: torch.Tensor, grad_s: torch.Tensor):  # type: ignore[override]
        (s,) = ctx.saved_tensors
        if grad_a is None:
            grad_a = torch.zeros_like(s)
        gs = grad_s if grad_s is not None else torch.zeros(0)
        return _load_extension().softplus_slope_backward(grad_a, gs, s, SOFTPLUS_BETA)


def _softplus_and_slope(z: torch.Tensor, fast: bool) -> tuple[torch.Tensor, torch.Tensor]:
    if fast and z.dtype == torch.float32 and fast_available():
        return _SoftplusSlope.apply(z)
    return softplus_and_slope_reference(z)


class _PEChain(torch.autograd.Function):
    """C++ chain rule of the positional encoding (``_encoding_kernel.cpp``): forward and its backward with
    respect to the gradient input."""

    @staticmethod
    def forward(ctx, gin_pe: torch.Tensor, pe: torch.Tensor, freqs: torch.Tensor):  # type: ignore[override]
        ctx.save_for_backward(pe, freqs)
        return _load_extension().pe_chain_forward(gin_pe.contiguous(), pe, freqs)

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):  # type: ignore[override]
        pe, freqs = ctx.saved_tensors
        return _load_extension().pe_chain_backward(grad_out.contiguous(), pe, freqs), None, None


def linear_blocks(blocks: list[torch.Tensor], weight: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
    """``torch.cat(blocks, -1) @ weight.T + bias`` without the concatenation: one product per input block
    with its columns of ``weight``, accumulated by ``addmm``.

    Same parameters, same values up to float summation order; autograd then computes an input gradient
    only for the blocks that need one (the positional encoding, the ray directions and the points do not:
    at 55 inputs that one (P, H) @ (H, 55) product was the slowest matrix product of the step) and never
    materialises or slices the (P, in) concatenation; the partial sums accumulate in place.

    Args:
        blocks: (P, d_i) tensors with ``sum(d_i) == weight.shape[1]`` (in the column order of ``weight``).
        weight: (out, in), e.g. ``Linear.weight`` or a leading column slice of it. bias: (out,) or (P, out).

    Returns:
        (P, out).
    """
    out = bias
    c = 0
    for i, x in enumerate(blocks):
        d = x.shape[-1]
        w = weight[:, c : c + d].t()
        # the first product writes a new (P, out) tensor; the others accumulate into it in place (an out-of-place
        # addmm would copy the (P, out) partial sum first; addmm's backward does not need it)
        out = torch.addmm(out, x, w) if i == 0 else out.addmm_(x, w)
        c += d
    if c != weight.shape[1]:
        raise ValueError(f"linear_blocks: blocks give {c} inputs, the weight takes {weight.shape[1]}")
    return out


class SDFNetwork(torch.nn.Module):
    """SDF field with analytic spatial gradient.

    Two layouts of MonoSDF's ``ImplicitNetwork(Grid)``:

    * grid variant (``spec`` given): input ``[grid features(x / R), PE(x)]``;
    * MLP variant (``spec=None``, MonoSDF / the MonoInstance release ``use_grid_feature = False``): input
      ``PE(x)`` alone, usually with a deeper MLP and ``skip`` (MonoSDF: 8 x 256, skip at layer 4).

    ``skip`` lists linear layers ``l`` (0-based positions in ``self.linears``, >= 1) whose input is
    ``[a_l, PE(x)] / sqrt(2)`` (IDR / MonoSDF ``skip_in``: the encoding re-enters the MLP; the layer
    before it outputs ``hidden - PE width`` so that the concatenation is ``hidden`` wide). ``weight_norm``:
    every SDF linear layer is weight-normalised (``torch.nn.utils.parametrizations.weight_norm``; MonoSDF:
    ``weight_norm = True``), applied after the geometric init.

    Args:
        spec: feature-grid layout, or None for the MLP variant. hidden: MLP width. layers: hidden layers.
        geo_features: size of the geometry feature passed to the colour network. radius: bounding-sphere
        radius R (normalised units). init_radius: geometric-init sphere radius. inside_out: rooms (cameras
        inside). fast_grid: use the C++ kernels (grid, softplus and slope, positional encoding and its
        chain rule). pe_frequencies: positional-encoding frequencies. skip / weight_norm: above.
    """

    def __init__(self, spec: GridSpec | None, hidden: int = 64, layers: int = 2, geo_features: int = 15, radius: float = 1.0,
                 init_radius: float = 0.6, inside_out: bool = True, fast_grid: bool = True, seed: int = 0,
                 pe_frequencies: int = 0, skip: tuple[int, ...] = (), weight_norm: bool = False) -> None:
        super().__init__()
        torch.manual_seed(seed)
        self.grid = FeatureGrid(spec, fast=fast_grid, seed=seed) if spec is not None else None
        self.fast = bool(fast_grid)
        self.radius = float(radius)
        self.pe_frequencies = int(pe_frequencies)
        self.active_levels = spec.levels if spec is not None else 0  # coarse-to-fine: finer levels read as 0 (set_active_levels)
        self.pe_freqs: torch.Tensor  # registered buffer (below): declared for the type checker
        self.register_buffer("pe_freqs", 2.0 ** torch.arange(self.pe_frequencies, dtype=torch.float32), persistent=False)
        self.n_grid = spec.out_dim if spec is not None else 0
        self.n_pe = 3 * (1 + 2 * self.pe_frequencies)
        dims = [self.n_grid + self.n_pe] + [hidden] * layers + [1 + geo_features]
        n_lin = len(dims) - 1
        self.skip = tuple(sorted(int(s) for s in skip))
        for s in self.skip:
            if not 1 <= s < n_lin:
                raise ValueError(f"skip layer {s} outside 1..{n_lin - 1} (the SDF MLP has {n_lin} linear layers)")
            if dims[s] <= self.n_pe:
                raise ValueError(f"skip at layer {s}: width {dims[s]} must exceed the encoding's {self.n_pe} inputs")
        outs = [dims[i + 1] - (self.n_pe if i + 1 in self.skip else 0) for i in range(n_lin)]
        self.linears = torch.nn.ModuleList(torch.nn.Linear(dims[i], outs[i]) for i in range(n_lin))
        self._geometric_init(init_radius, inside_out)
        if weight_norm:
            for lin in self.linears:
                torch.nn.utils.parametrizations.weight_norm(lin)

    def set_active_levels(self, n: int) -> None:
        """Use only the ``n`` coarsest grid levels (the others' features and Jacobians read as 0, so their
        table entries get no gradient): progressive level activation (Neuralangelo / instant-angelo)."""
        if self.grid is not None:
            self.active_levels = max(0, min(int(n), self.grid.spec.levels))

    def level_mask(self, feat: torch.Tensor) -> torch.Tensor:
        """``feat`` (P, L * F) with the features of the inactive (finer) levels set to 0 (level-major layout)."""
        if self.grid is None or self.active_levels >= self.grid.spec.levels:
            return feat
        return feat * (torch.arange(feat.shape[-1]) < self.active_levels * self.grid.spec.features).to(feat.dtype)

    def encode(self, u: torch.Tensor) -> torch.Tensor:
        """Positional encoding of ``u = x`` (P, 3, normalised units) -> (P, 3 + 6F) ``[u, sin(f_k u), cos(f_k u)]`` with the
        k-major layout ``[sin k=0 xyz, ..., sin k=F-1 xyz, cos ...]`` (``u`` alone without frequencies).
        C++ kernel (``_encoding_kernel.cpp``) when the fast path is on; :meth:`encode_reference` is its twin."""
        if self.pe_frequencies and self.fast and u.dtype == torch.float32 and fast_available():
            return _load_extension().pe_encode(u.contiguous(), self.pe_freqs)
        return self.encode_reference(u)

    def encode_reference(self, u: torch.Tensor) -> torch.Tensor:
        """:meth:`encode` in PyTorch ops (the slow twin)."""
        if self.pe_frequencies == 0:
            return u
        fu = u[:, None, :] * self.pe_freqs[None, :, None]  # (P, F, 3)
        P = u.shape[0]
        return torch.cat([u, torch.sin(fu).reshape(P, -1), torch.cos(fu).reshape(P, -1)], dim=-1)

    def pe_chain(self, gin_pe: torch.Tensor, pe: torch.Tensor) -> torch.Tensor:
        """d sdf / d u through the encoding (chain rule of :meth:`encode`): ``gin_pe`` (P, 3 + 6F) is the
        gradient of the SDF output with respect to the encoding ``pe`` (P, 3 + 6F) -> (P, 3). Differentiable
        with respect to ``gin_pe`` (the encoding depends on the points only, which need no gradient). C++
        kernel when the fast path is on; :meth:`pe_chain_reference` is its twin."""
        if self.pe_frequencies == 0:
            return gin_pe
        if self.fast and gin_pe.dtype == torch.float32 and fast_available():
            return _PEChain.apply(gin_pe, pe.detach(), self.pe_freqs)
        return self.pe_chain_reference(gin_pe, pe)

    def pe_chain_reference(self, gin_pe: torch.Tensor, pe: torch.Tensor) -> torch.Tensor:
        """:meth:`pe_chain` in PyTorch ops (the slow twin): ``gin_u + sum_k f_k (gin_sin cos - gin_cos sin)``."""
        if self.pe_frequencies == 0:
            return gin_pe
        F_ = self.pe_frequencies
        P = gin_pe.shape[0]
        sin, cos = pe[:, 3 : 3 + 3 * F_].reshape(P, F_, 3), pe[:, 3 + 3 * F_ :].reshape(P, F_, 3)
        g_sin = gin_pe[:, 3 : 3 + 3 * F_].reshape(P, F_, 3)
        g_cos = gin_pe[:, 3 + 3 * F_ :].reshape(P, F_, 3)
        return gin_pe[:, :3] + ((g_sin * cos - g_cos * sin) * self.pe_freqs[None, :, None]).sum(1)

    def _geometric_init(self, r: float, inside_out: bool) -> None:
        """IDR geometric init: a sphere SDF of radius r in normalised units. Grid features and
        positional-encoding frequencies start with zero weights (first layer, and the encoding's columns
        of every skip layer): the MLP sees only x at init."""
        for i, module in enumerate(self.linears):
            lin = cast(torch.nn.Linear, module)
            out_dim, in_dim = lin.weight.shape
            if i == len(self.linears) - 1:
                mean = math.sqrt(math.pi) / math.sqrt(in_dim)
                torch.nn.init.normal_(lin.weight, mean=-mean if inside_out else mean, std=1e-4)
                torch.nn.init.constant_(lin.bias, r if inside_out else -r)
            else:
                torch.nn.init.constant_(lin.bias, 0.0)
                torch.nn.init.normal_(lin.weight, 0.0, math.sqrt(2) / math.sqrt(out_dim))
                if i == 0:  # grid features and PE frequencies start switched off: the MLP sees only x at init
                    torch.nn.init.constant_(lin.weight[:, : self.n_grid], 0.0)
                    torch.nn.init.constant_(lin.weight[:, self.n_grid + 3 :], 0.0)
                elif i in self.skip:  # the re-entering encoding's frequencies (IDR: weight[:, -(d_in - 3):] = 0)
                    torch.nn.init.constant_(lin.weight[:, in_dim - self.n_pe + 3 :], 0.0)

    def forward(self, x: torch.Tensor, with_gradient: bool = True) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Evaluate the field.

        Args:
            x: (P, 3) points, normalised units (inside the sphere of radius R).
            with_gradient: also return d sdf / d x.

        Returns:
            sdf (P,) in normalised units (clamped to the sphere), geometry feature (P, G), gradient (P, 3) or None.
        """
        pe = self.encode(x)  # (P, 3 + 6 F_pe)
        blocks = [pe]
        jac = None
        if self.grid is not None:
            feat, jac = self.grid(x / self.radius, with_jacobian=with_gradient)  # d feat / d (x / R)
            feat = self.level_mask(feat)
            jac = None if jac is None else self.level_mask(jac)  # (P, 3, L * F): the same mask on the last axis
            blocks = [feat, pe]
        n_lin = len(self.linears)
        # each layer's weight read once (weight norm recomputes it on every read); a skip layer takes
        # [a, pe] / sqrt(2), i.e. its weight / sqrt(2) on [a, pe]
        ws = [cast(torch.Tensor, lin.weight) * _INV_SQRT2 if i in self.skip else cast(torch.Tensor, lin.weight) for i, lin in enumerate(self.linears)]
        bs = [cast(torch.Tensor, lin.bias) for lin in self.linears]
        a, slope = _softplus_and_slope(linear_blocks(blocks, ws[0], bs[0]), self.fast)  # no (P, in) concatenation
        slopes = [slope]
        for i in range(1, n_lin - 1):
            z = linear_blocks([a, pe], ws[i], bs[i]) if i in self.skip else torch.addmm(bs[i], a, ws[i].t())
            a, slope = _softplus_and_slope(z, self.fast)
            slopes.append(slope)
        out = linear_blocks([a, pe], ws[-1], bs[-1]) if n_lin - 1 in self.skip else torch.addmm(bs[-1], a, ws[-1].t())
        sdf_net = out[:, 0]  # normalised units (MonoSDF: the MLP output is the SDF)
        geo = out[:, 1:]
        grad = None
        if with_gradient:
            # explicit vector-Jacobian product of the SDF output (differentiable, first-order ops only):
            # g = d sdf / d (input of layer i), walked from the last layer to the first; the encoding's
            # share of every skip layer's input gradient is collected in g_pe
            # d sdf / d (input of the last layer) is its weight row, the same for every point: while g is
            # that row (g is None), the row is folded into the next layer's weight, (s * w) @ W =
            # s @ (w[:, None] * W), instead of a (P, H) product and its backward
            w_row = ws[-1][0]
            g: torch.Tensor | None = None
            g_pe: torch.Tensor | None = None
            for i in range(n_lin - 1, 0, -1):
                if i in self.skip:
                    if g is None:
                        g = w_row.expand(a.shape[0], w_row.shape[0])
                    h = ws[i].shape[1] - self.n_pe
                    g_pe = g[:, h:] if g_pe is None else g_pe + g[:, h:]
                    g = g[:, :h]
                if i > 1:
                    # (P, in of layer i - 1)
                    g = slopes[i - 1] @ (w_row[:, None] * ws[i - 1]) if g is None else (g * slopes[i - 1]) @ ws[i - 1]
            g0 = slopes[0] * w_row if g is None else g * slopes[0]  # (P, H): d sdf / d (first layer pre-activation)
            c = self.n_grid
            # one product per input block of the first layer (grid / encoding), then each block's own chain rule
            gin_pe = g0 @ ws[0][:, c:]
            grad = self.pe_chain(gin_pe if g_pe is None else gin_pe + g_pe, pe)  # (P, 3)
            if self.grid is not None:
                assert jac is not None  # the grid returns the Jacobian when asked (with_jacobian=with_gradient)
                grad = jacobian_contract(jac, g0 @ ws[0][:, :c], self.fast) / self.radius + grad  # the grid reads x / R
        # bounding-sphere clamp (MonoSDF): every ray terminates inside the sphere
        norm = x.norm(dim=-1)
        sphere = self.radius - norm
        clamp = sphere < sdf_net
        sdf = torch.where(clamp, sphere, sdf_net)
        if with_gradient:
            assert grad is not None  # set above (same condition)
            grad = torch.where(clamp[:, None], -x / norm.clamp_min(1e-9)[:, None], grad)
        return sdf, geo, grad


def sdf_gradient_autograd(net: SDFNetwork, x: torch.Tensor, create_graph: bool = False) -> torch.Tensor:
    """Slow, obviously-correct twin of the explicit gradient: ``torch.autograd.grad`` of the SDF
    (through the reference grid path, which is differentiable w.r.t. x). (P, 3). ``create_graph``: the
    result is differentiable w.r.t. the parameters (autograd's double backward: the twin of the
    explicit gradient's own backward, which the eikonal and normal losses use)."""
    from methods.monosdf.grid import interpolate_reference

    x = x.detach().requires_grad_(True)
    pe = net.encode_reference(x)
    a = pe
    if net.grid is not None:
        feat, _ = interpolate_reference(net.grid.table, x / net.radius, net.grid.spec, with_jacobian=False)
        a = torch.cat([net.level_mask(feat), pe], dim=-1)
    for i, lin in enumerate(net.linears):
        if i in net.skip:
            a = torch.cat([a, pe], dim=-1) / math.sqrt(2)
        a = lin(a) if i == len(net.linears) - 1 else F.softplus(lin(a), beta=SOFTPLUS_BETA)
    sdf = torch.minimum(a[:, 0], net.radius - x.norm(dim=-1))
    return torch.autograd.grad(sdf.sum(), x, create_graph=create_graph)[0]


class ColorNetwork(torch.nn.Module):
    """MonoSDF's rendering network, scaled down: ``[x, view dir, normal, geo feature, image code] -> MLP ->
    sigmoid RGB``.

    ``appearance_dim > 0`` gives every training image a learned code of that size (MonoSDF's and the
    MonoInstance release's ``per_image_code = True``: 32-d, NeRF-in-the-wild), so per-image exposure /
    white balance is explained by the code instead of by the geometry. Codes start at U(-1e-4, 1e-4)
    (MonoSDF).

    ``view_dependent=False`` feeds zeros for the view direction: a Lambertian radiance field, which cannot
    paint one surface point differently for different views (a diagnostic; MonoSDF's network is view
    dependent)."""

    def __init__(self, geo_features: int = 15, hidden: int = 64, layers: int = 1, appearance_dim: int = 0, num_images: int = 0,
                 view_dependent: bool = True) -> None:
        super().__init__()
        self.view_dependent = bool(view_dependent)
        self.appearance_dim = int(appearance_dim)
        self.codes = torch.nn.Parameter(torch.empty(int(num_images) if self.appearance_dim else 0, self.appearance_dim).uniform_(-1e-4, 1e-4))
        dims = [9 + geo_features + self.appearance_dim] + [hidden] * layers + [3]
        mods: list[torch.nn.Module] = []
        for i in range(len(dims) - 1):
            mods.append(torch.nn.Linear(dims[i], dims[i + 1]))
            if i < len(dims) - 2:
                mods.append(torch.nn.ReLU())
        self.mlp = torch.nn.Sequential(*mods)

    def forward(self, x: torch.Tensor, view_dirs: torch.Tensor, normals: torch.Tensor, geo: torch.Tensor,
                image: int | torch.Tensor | None = None) -> torch.Tensor:
        """x, view_dirs, normals: (P, 3); geo: (P, G); image: training slot whose code is used, an int or
        (P,) per point (None = the mean code, for views without one) -> rgb (P, 3) in [0, 1]."""
        if not self.view_dependent:
            view_dirs = torch.zeros_like(view_dirs)
        first = cast(torch.nn.Linear, self.mlp[0])
        n_point = first.in_features - self.appearance_dim  # per-point inputs: x, view dir, normal, geo feature
        bias: torch.Tensor = first.bias
        if self.appearance_dim:
            # the code is constant per image: its share of the first layer is a per-image bias
            # (W_code @ code + b), computed once per image instead of a (P, appearance_dim) input block
            w_code = first.weight[:, n_point:]
            if isinstance(image, torch.Tensor):
                bias = torch.addmm(first.bias, self.codes, w_code.t())[image]  # (P, hidden)
            else:
                code = self.codes.mean(0) if image is None else self.codes[int(image)]
                bias = first.bias + w_code @ code  # (hidden,)
        # one (P, 24) block: four small products (K = 3) would each pass over the (P, hidden) output (measured slower)
        h = linear_blocks([torch.cat([x, view_dirs, normals, geo], dim=-1)], first.weight[:, :n_point], bias)
        return torch.sigmoid(self.mlp[1:](h))

    def forward_reference(self, x: torch.Tensor, view_dirs: torch.Tensor, normals: torch.Tensor, geo: torch.Tensor,
                          image: int | torch.Tensor | None = None) -> torch.Tensor:
        """Slow, obviously-correct twin of :meth:`forward`: the MLP on the concatenated input
        ``[x, view dir, normal, geo feature, image code]`` (tests compare them)."""
        parts = [x, view_dirs if self.view_dependent else torch.zeros_like(view_dirs), normals, geo]
        if self.appearance_dim:
            if isinstance(image, torch.Tensor):
                parts.append(self.codes[image])
            else:
                code = self.codes.mean(0) if image is None else self.codes[int(image)]
                parts.append(code.expand(x.shape[0], self.appearance_dim))
        return torch.sigmoid(self.mlp(torch.cat(parts, dim=-1)))


class LaplaceDensity(torch.nn.Module):
    """VolSDF density ``sigma(s) = (1 / beta) * (0.5 + 0.5 * sign(s) * expm1(-|s| / beta))`` with learnable
    ``beta = |beta_param| + beta_min`` (MonoSDF: init 0.1, beta_min 1e-4). Uses ``expm1(-|s|/beta)`` in
    (-1, 0], so extreme SDF values cannot overflow."""

    def __init__(self, beta_init: float = 0.1, beta_min: float = 1e-4) -> None:
        super().__init__()
        self.beta_param = torch.nn.Parameter(torch.tensor(float(beta_init)))
        self.beta_min = float(beta_min)

    def beta(self) -> torch.Tensor:
        return self.beta_param.abs() + self.beta_min

    def forward(self, sdf: torch.Tensor, beta: torch.Tensor | None = None) -> torch.Tensor:
        b = self.beta() if beta is None else beta
        return (0.5 + 0.5 * torch.sign(sdf) * torch.expm1(-sdf.abs() / b)) / b
