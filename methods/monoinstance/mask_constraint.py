"""Uncertainty-based instance mask constraint (paper Sec. 3.3; official ``model/network.py: cal_warp_views``).

For a ray of instance k whose depth/normal weight is 0 (certainty below the cut-off, i.e. the prior is
not trusted there), every ray sample is projected into ``n_source`` nearby views of the same instance,
where colour and the instance mask are sampled bilinearly; samples outside the image or the source
mask count zero, and the warped colour is ``sum_i w_i valid_i c_src_i``. A pixel counts if
``sum_i w_i valid_i > 0.01`` and at least one sample lands in the mask. The loss is the L1 against the
reference pixel colour, averaged per source view, then over instances (weight 0.4).

Nearby views of an instance: the ray through the instance's bounding-box centre in each view; a
source must see the instance with an angle to the reference ray in (``min_angle``, ``max_angle``)
degrees and a ray-ray distance below ``max_ray_dist`` (normalised units); the closest ``n_source``
by ray distance are kept. Instances must appear in >= ``min_views`` views with > ``min_area_frac`` x
H x W pixels.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from methods.monosdf.render import RenderOutput


def _ray_distance(o1: np.ndarray, d1: np.ndarray, o2: np.ndarray, d2: np.ndarray) -> float:
    """Shortest distance between two lines (unit directions)."""
    n = np.cross(d1, d2)
    nn = np.linalg.norm(n)
    if nn < 1e-9:  # parallel
        return float(np.linalg.norm(np.cross(o2 - o1, d1)))
    return float(abs((o2 - o1) @ n) / nn)


class MaskConstraint:
    """Callable extra loss for :class:`methods.monosdf.trainer.MonoSDFTrainer` (``extra_losses``)."""

    def __init__(self, trainer: Any, instance_ids: np.ndarray, is_background: dict[int, bool], untrusted: np.ndarray,
                 cfg: dict[str, Any]) -> None:
        """``untrusted``: (V, H, W) bool, rays whose prior weight is 0 (certainty below the cut-off)."""
        self.weight = float(cfg["mask_weight"])
        self.untrusted = torch.from_numpy(untrusted.reshape(untrusted.shape[0], -1))
        self.cfg = cfg
        scene, views = trainer.scene, trainer.views
        V, H, W = instance_ids.shape
        self.H, self.W = H, W
        self.ids = torch.from_numpy(instance_ids.astype(np.int64)).reshape(V, -1)
        self.images = torch.from_numpy(np.ascontiguousarray(scene.images[views].transpose(0, 3, 1, 2)).astype(np.float32))
        self.ids_img = torch.from_numpy(instance_ids.astype(np.int64))
        rays = trainer.rays
        self.scale = rays.scale
        from methods.monosdf.rays import normalisation

        self.centre = torch.from_numpy(normalisation(scene)[0].astype(np.float32))
        self.K = torch.from_numpy(scene.intrinsics[views].astype(np.float32))
        self.w2c = torch.from_numpy(np.linalg.inv(scene.cam_to_world[views]).astype(np.float32))
        min_area = float(cfg["mask_min_area_frac"]) * H * W
        centres: dict[int, dict[int, np.ndarray]] = {}  # instance -> view -> unit ray through bbox centre
        for v in range(V):
            for k in np.unique(instance_ids[v]):
                if k == 0 or is_background.get(int(k), False):
                    continue
                ys, xs = np.nonzero(instance_ids[v] == k)
                if len(ys) <= min_area:
                    continue
                cy, cx = int(round((ys.min() + ys.max()) / 2)), int(round((xs.min() + xs.max()) / 2))
                centres.setdefault(int(k), {})[v] = rays.dirs[v, cy * W + cx].numpy().astype(np.float64)
        origins = rays.origins.numpy().astype(np.float64)
        self.sources: dict[tuple[int, int], list[int]] = {}
        lo, hi = np.deg2rad(cfg["mask_min_angle_deg"]), np.deg2rad(cfg["mask_max_angle_deg"])
        for k, per_view in centres.items():
            if len(per_view) < int(cfg["mask_min_views"]):
                continue
            for v, d in per_view.items():
                cands = []
                for j, dj in per_view.items():
                    if j == v:
                        continue
                    ang = np.arccos(np.clip(d @ dj, -1.0, 1.0))
                    dist = _ray_distance(origins[v], d, origins[j], dj)
                    if lo < ang < hi and dist < float(cfg["mask_max_ray_dist"]):
                        cands.append((dist, j))
                if cands:
                    self.sources[(v, k)] = [j for _, j in sorted(cands)[: int(cfg["mask_n_source"])]]

    def __call__(self, trainer: Any, view: int, pixels: torch.Tensor, out: RenderOutput) -> dict[str, tuple[float, torch.Tensor]]:
        ids = self.ids[view, pixels]
        untrusted = self.untrusted[view, pixels]
        per_instance = []
        for k in torch.unique(ids[untrusted]).tolist():
            srcs = self.sources.get((view, int(k)))
            if not srcs:
                continue
            sel = torch.nonzero(untrusted & (ids == k))[:, 0]
            o = trainer.rays.origins[view]
            d = trainer.rays.dirs[view, pixels[sel]]
            pts = (o[None, None, :] + d[:, None, :] * out.t[sel][..., None]) * self.scale + self.centre  # world (r, S, 3)
            w = out.weights[sel]  # (r, S), differentiable
            ref = trainer.rgb[view, pixels[sel]]  # (r, 3)
            losses = []
            for j in srcs:
                pc = pts @ self.w2c[j, :3, :3].T + self.w2c[j, :3, 3]
                z = pc[..., 2].clamp_min(1e-6)
                u = self.K[j, 0, 0] * pc[..., 0] / z + self.K[j, 0, 2]
                v = self.K[j, 1, 1] * pc[..., 1] / z + self.K[j, 1, 2]
                inside = (pc[..., 2] > 1e-6) & (u >= 0) & (u <= self.W - 1) & (v >= 0) & (v <= self.H - 1)
                grid = torch.stack([u / (self.W - 1) * 2 - 1, v / (self.H - 1) * 2 - 1], -1).reshape(1, -1, 1, 2)
                src = torch.cat([self.images[j], (self.ids_img[j] == k).float()[None]], 0)[None]  # (1, 4, H, W)
                samp = F.grid_sample(src, grid, mode="bilinear", align_corners=True).reshape(4, *u.shape)  # (4, r, S)
                valid = (inside & (samp[3] > 0.5)).float()
                wv = w * valid
                warped = (wv[..., None] * samp[:3].permute(1, 2, 0)).sum(1)  # (r, 3)
                count = (wv.sum(-1) > 0.01) & (valid.sum(-1) > 0)
                if count.any():
                    losses.append((warped[count] - ref[count]).abs().mean())
            if losses:
                per_instance.append(torch.stack(losses).mean())
        if not per_instance:
            return {"mask": (self.weight, torch.zeros(()))}
        return {"mask": (self.weight, torch.stack(per_instance).mean())}
