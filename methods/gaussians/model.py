"""The Gaussian scene model: parameters, activations, SH colour (degree 0-1), initialisation, rendering.

Parameters (raw, optimised; held in a dict of leaf tensors so the strategy can resize them):

======================  ============  =======================================================
name                    shape         activation
======================  ============  =======================================================
``means``               (N, 3)        none (world metres)
``scales``              (N, 3)        ``exp`` -> standard deviations in metres
``quats``               (N, 4)        normalised in the rasteriser, ``(w, x, y, z)``
``opacities``           (N,)          ``sigmoid``
``sh0``                 (N, 1, 3)     DC SH coefficient: colour = ``SH_C0 sh0 + 0.5``
``shN``                 (N, 3, 3)     degree-1 SH coefficients (unused at ``sh_degree: 0``)
======================  ============  =======================================================

Initialisation from the sparse views (:func:`init_points_from_views`): we have no COLMAP. FSGS and
3DGS start from the SfM points of the training views; our stand-in is a small **plane sweep** over the
3 training views (photometric 3 x 3 patch SAD against the other training views over ``n_depths``
fronto-parallel planes, uniform in inverse depth between the LLFF near / far bounds), keeping the
pixels whose best cost is low and clearly better than the mean cost (a sparse, "SfM-like" set of
matched points). Like SfM's tracks, a match must be seen in every other training view
(``all_views``), and the patches are compared after removing each patch's mean (``cost="zero_mean"``;
the sensor's per-view exposure gain otherwise biases the match towards wrong planes). Measured on the
hand-held LLFF-like scenes (64 planes; fraction of matched pixels whose depth is within 10 % of the GT):
SAD over valid views, ratio 0.5 (the earlier default): 0.16-0.33, median depth / GT 0.36-0.77 (points far
in front of the surfaces); zero-mean, all views, ratio 0.3 (the default): 0.77-0.95, median 0.99-1.02,
with ~1/3 as many points (``scripts/fewshot_properties.py``, docs/tables.md "Table 3 scenes"). Optionally
``n_random`` points at random pixels of the training views and random inverse depth within the bounds
(3DGS's random init; the configs' ``init_random`` is 0, as FSGS / 3DGS with SfM points). Uses only the
training images, poses and bounds: no priors, no GT, and it is the same for all three rows.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from methods.gaussians.rasterize import rasterize_gaussians
from metrics.camera import pixel_rays, pixels_to_rays, to_world

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199


def sh_to_color(sh0: torch.Tensor, shN: torch.Tensor, dirs: torch.Tensor, degree: int) -> torch.Tensor:
    """Colour (N, 3) from SH of degree 0 or 1; ``dirs`` (N, 3) unit viewing directions (camera -> Gaussian)."""
    c = SH_C0 * sh0[:, 0]
    if degree >= 1:
        x, y, z = dirs[:, 0:1], dirs[:, 1:2], dirs[:, 2:3]
        c = c - SH_C1 * y * shN[:, 0] + SH_C1 * z * shN[:, 1] - SH_C1 * x * shN[:, 2]
    return (c + 0.5).clamp_min(0.0)


def render(params: dict[str, torch.Tensor], viewmat: torch.Tensor, K: torch.Tensor, width: int, height: int, sh_degree: int,
           background: torch.Tensor, **kw: Any) -> dict[str, Any]:
    """Render the model from one camera (``viewmat`` world-to-camera, OpenCV axes; ``K`` pixels)."""
    means = params["means"]
    cam_centre = -viewmat[:3, :3].T @ viewmat[:3, 3]
    dirs = F.normalize(means.detach() - cam_centre, dim=-1)
    colors = sh_to_color(params["sh0"], params["shN"], dirs, sh_degree)
    return rasterize_gaussians(means, params["quats"], torch.exp(params["scales"]), torch.sigmoid(params["opacities"]), colors,
                               viewmat, K, width, height, background=background, **kw)


def _patch_features(img: torch.Tensor) -> torch.Tensor:
    """(H, W, 3) -> (1, 27, H, W) 3 x 3 patches (replicate padding)."""
    x = img.permute(2, 0, 1)[None]
    x = F.pad(x, (1, 1, 1, 1), mode="replicate")
    return F.unfold(x, 3).reshape(1, 27, img.shape[0], img.shape[1])


def _centre(patches: torch.Tensor, cost: str) -> torch.Tensor:
    """(M, 27) 3 x 3 x 3 patch vectors (channel-major, as ``_patch_features``) minus each patch's
    per-channel mean for ``cost == "zero_mean"``; unchanged for ``"sad"``."""
    if cost == "sad":
        return patches
    p = patches.reshape(-1, 3, 9)
    return (p - p.mean(-1, keepdim=True)).reshape(-1, 27)


@torch.no_grad()
def init_points_from_views(images: np.ndarray, Ks: np.ndarray, c2ws: np.ndarray, near: float, far: float, n_depths: int,
                           n_random: int, max_sweep_points: int, rng: np.random.Generator,
                           cost_max: float = 0.06, cost_ratio: float = 0.3, cost: str = "zero_mean",
                           all_views: bool = True) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """Initial points from the training views (see the module docstring).

    Args:
        images: (V, H, W, 3) float in [0, 1]; Ks: (V, 3, 3); c2ws: (V, 4, 4) camera-to-world (OpenCV axes).
        near, far: depth bounds (metres). n_depths: planes of the sweep. n_random: random points.
        max_sweep_points: cap on the matched points (random subset). rng: seeded generator.
        cost_max: max mean absolute colour difference per channel of an accepted match.
        cost_ratio: best cost must be below ``cost_ratio`` x the mean cost over the planes.
        cost: ``"zero_mean"`` (each 3 x 3 x 3 patch minus its per-channel mean, then SAD) or ``"sad"``.
        all_views: a plane counts only where the pixel projects into every other view (else: any).

    Returns:
        points (P, 3) float64 world, colours (P, 3) float32, counts ``{"sweep": ..., "random": ...}``.
    """
    if cost not in ("zero_mean", "sad"):
        raise ValueError(f"cost must be 'zero_mean' or 'sad', got {cost!r}")
    V, H, W, _ = images.shape
    imgs = torch.from_numpy(images).float()
    feats = [_patch_features(imgs[i]) for i in range(V)]
    inv_d = torch.linspace(1.0 / far, 1.0 / near, n_depths, dtype=torch.float64)
    depths = 1.0 / inv_d
    pts_all, col_all = [], []
    for i in range(V):
        rays = torch.from_numpy(pixel_rays(Ks[i], H, W).reshape(-1, 3))  # [HW, 3], z = 1
        c2w = torch.from_numpy(c2ws[i])
        ref = _centre(feats[i].reshape(27, -1).T.float(), cost)  # [HW, 27]
        total = torch.zeros(n_depths, H * W)
        nvalid = torch.zeros(n_depths, H * W)
        for j in range(V):
            if j == i:
                continue
            w2c = torch.linalg.inv(torch.from_numpy(c2ws[j]))
            Kj = torch.from_numpy(Ks[j])
            for k, d in enumerate(depths):
                Xw = (rays * d) @ c2w[:3, :3].T + c2w[:3, 3]
                Xc = Xw @ w2c[:3, :3].T + w2c[:3, 3]
                z = Xc[:, 2]
                uv = (Xc @ Kj.T)[:, :2] / z.clamp_min(1e-6)[:, None]
                ok = (z > 1e-3) & (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
                grid = torch.stack([uv[:, 0] / (W - 1) * 2 - 1, uv[:, 1] / (H - 1) * 2 - 1], -1).float()[None, None]
                samp = _centre(F.grid_sample(feats[j], grid, mode="bilinear", align_corners=True)[0, :, 0].T, cost)  # [HW, 27]
                c = (samp - ref).abs().mean(1)
                total[k] += torch.where(ok, c, torch.zeros_like(c))
                nvalid[k] += ok.float()
        seen = nvalid == V - 1 if all_views else nvalid > 0
        mean_cost = torch.where(seen, total / nvalid.clamp_min(1), torch.full_like(total, float("inf")))
        best, arg = mean_cost.min(0)
        finite = torch.isfinite(mean_cost)
        avg = torch.where(finite, mean_cost, torch.zeros_like(mean_cost)).sum(0) / finite.sum(0).clamp_min(1)
        good = (best < cost_max) & (best < cost_ratio * avg) & (finite.sum(0) > n_depths // 2)
        idx = torch.nonzero(good).squeeze(1)
        d = depths[arg[idx]]
        X = (rays[idx] * d[:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
        pts_all.append(X.numpy())
        col_all.append(imgs[i].reshape(-1, 3)[idx].numpy())
    pts = np.concatenate(pts_all) if pts_all else np.zeros((0, 3))
    cols = np.concatenate(col_all) if col_all else np.zeros((0, 3), np.float32)
    if len(pts) > max_sweep_points:
        keep = rng.choice(len(pts), max_sweep_points, replace=False)
        pts, cols = pts[keep], cols[keep]
    n_sweep = len(pts)
    # random points: random training view, random pixel, random inverse depth in the bounds
    if n_random > 0:
        views = rng.integers(0, V, n_random)
        uu = rng.uniform(-0.5, W - 0.5, n_random)
        vv = rng.uniform(-0.5, H - 0.5, n_random)
        dd = 1.0 / rng.uniform(1.0 / far, 1.0 / near, n_random)
        rp, rc = [], []
        for i in range(V):
            m = views == i
            rp.append(to_world(pixels_to_rays(Ks[i], uu[m], vv[m]) * dd[m, None], c2ws[i]))
            ui = np.clip(np.round(uu[m]).astype(int), 0, W - 1)
            vi = np.clip(np.round(vv[m]).astype(int), 0, H - 1)
            rc.append(images[i][vi, ui])
        pts = np.concatenate([pts] + rp)
        cols = np.concatenate([cols] + rc)
    return pts, cols.astype(np.float32), {"sweep": int(n_sweep), "random": int(len(pts) - n_sweep)}


def init_params(points: np.ndarray, colors: np.ndarray, init_opacity: float, max_scale: np.ndarray | None = None) -> dict[str, torch.Tensor]:
    """Raw parameters from points: isotropic scale = RMS distance to the 3 nearest neighbours (3DGS),
    capped by ``max_scale`` (P,) metres when given (our cap on the screen footprint, see ``init_max_px``)."""
    from scipy.spatial import cKDTree

    n = len(points)
    if n < 4:
        raise ValueError(f"need at least 4 initial points, got {n}")
    dist, _ = cKDTree(points).query(points, k=4)
    s = np.sqrt(np.maximum((dist[:, 1:] ** 2).mean(1), 1e-12))
    if max_scale is not None:
        s = np.minimum(s, max_scale)
    p = {
        "means": torch.tensor(points, dtype=torch.float32),
        "scales": torch.tensor(np.log(s), dtype=torch.float32)[:, None].repeat(1, 3),
        "quats": torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(n, 1),
        "opacities": torch.full((n,), math.log(init_opacity / (1 - init_opacity))),
        "sh0": ((torch.tensor(colors, dtype=torch.float32) - 0.5) / SH_C0)[:, None, :],
        "shN": torch.zeros(n, 3, 3),
    }
    return {k: v.requires_grad_() for k, v in p.items()}
