"""Uncertainty-based instance mask constraint (paper Sec. 3.3; official ``model/network.py: cal_warp_views``,
``model/loss.py: get_warp_rgb_loss``).

For a ray of instance k whose depth/normal weight is 0 (certainty below the cut-off, i.e. the prior is
not trusted there), every ray sample is projected into ``n_source`` nearby views of the same instance,
where colour and the instance mask are sampled bilinearly; samples outside the image or the source
mask count zero, and the warped colour is ``sum_i w_i valid_i c_src_i``. The loss is the L1 (mean over the
three channels) against the reference pixel colour, weight 0.4.

Where our port and the official code can differ, a config key chooses (default: the code; docs/uncertainty.md,
"Mask constraint: official code vs ours"):

* ``mask_hit_threshold``: a sample is in the source mask if the bilinear mask value exceeds it (code: 0, about
  1 px of dilation; an earlier default here: 0.5).
* ``mask_count_rule``: which rays count. ``code``: ``sum_i w_i inside_i > 0.01`` (projections inside the image
  carry weight) and at least one sample in the mask; ``ours``: ``sum_i w_i valid_i > 0.01`` (weight inside
  the mask) and at least one valid sample.
* ``mask_source_choice``: ``random`` (code): ``n_source`` of all valid nearby views drawn at random every
  step; ``nearest``: the fixed ``n_source`` nearest by ray distance.
* ``mask_erode_px``: an instance's rays come from its mask eroded by this square (code: 2; 0 = the mask).
* ``mask_renormalise`` (a DIAGNOSTIC, neither code nor paper): divide the warped colour by ``sum_i w_i valid_i``,
  which removes the darkening a spread-out or partly-outside ray weight causes (the targeted experiment of
  the mechanism in docs/uncertainty.md).
* ``mask_normalisation``. ``code``: per source view, the sum over counted rays / (their count + 1e-6) (0
  without any); the mean over the instance's sources, empty ones counting 0; the sum over instances divided
  by the number of the view's valid instances (those with source views), also those with no untrusted ray
  in the batch. ``ours``: means over the counted rays, the sources with any, and the instances with any
  (1.5-3x stronger where most sources or instances are empty).

Nearby views of an instance: the ray through the instance's bounding-box centre in each view; a
source must see the instance with an angle to the reference ray in (``min_angle``, ``max_angle``)
degrees and a ray-ray distance below ``max_ray_dist`` (normalised units); ``n_source`` of them are used
per step (``mask_source_choice``). Instances must appear in >= ``min_views`` views with > ``min_area_frac`` x
H x W pixels.

Diagnostics (:meth:`MaskConstraint.diagnostics`, averaged per step since the last call, in every snapshot's
diagnostics and so in every job result's curve and in the study): ``mask_untrusted_rays`` (untrusted instance
rays in the batch), ``mask_rays`` (rays counted, summed over source views), ``mask_instances`` (instances with
a counted ray) of ``mask_instances_valid``, ``mask_wvalid_mean`` (mean ``sum_i w_i valid_i`` of the counted
rays: well below 1 means the weight is spread along the ray or lands outside the source mask) and
``mask_color_gap`` (mean reference - warped colour of the counted rays: > 0 means the warped colour is darker;
measured as what makes the term hurt in docs/uncertainty.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from methods.monoinstance.config import MonoInstanceConfig
from methods.monosdf.render import RenderOutput


def _ray_distance(o1: np.ndarray, d1: np.ndarray, o2: np.ndarray, d2: np.ndarray) -> float:
    """Shortest distance between two lines (unit directions)."""
    n = np.cross(d1, d2)
    nn = np.linalg.norm(n)
    if nn < 1e-9:  # parallel
        return float(np.linalg.norm(np.cross(o2 - o1, d1)))
    return float(abs((o2 - o1) @ n) / nn)


def eroded_instances(instance_ids: np.ndarray, size: int) -> np.ndarray:
    """(V, H, W) instance ids with every instance's mask eroded by a ``size`` x ``size`` square (the official
    code takes an instance's rays from its 2 x 2-eroded mask, cv2 style: the image border does not erode);
    ``size`` <= 1 returns the ids unchanged."""
    if size <= 1:
        return instance_ids.astype(np.int64)
    from scipy.ndimage import binary_erosion

    out = np.zeros(instance_ids.shape, dtype=np.int64)
    structure = np.ones((size, size), dtype=bool)
    for v in range(instance_ids.shape[0]):
        for k in np.unique(instance_ids[v]):
            if k == 0:
                continue
            keep = binary_erosion(instance_ids[v] == k, structure=structure, border_value=1)
            out[v][keep] = k
    return out


class MaskConstraint:
    """Callable extra loss for :class:`methods.monosdf.trainer.MonoSDFTrainer` (``extra_losses``)."""

    def __init__(self, trainer: Any, instance_ids: np.ndarray, is_background: dict[int, bool], untrusted: np.ndarray,
                 cfg: MonoInstanceConfig) -> None:
        """``untrusted``: (V, H, W) bool, rays whose prior weight is 0 (certainty below the cut-off)."""
        self.weight = cfg.mask_weight
        self.untrusted = torch.from_numpy(untrusted.reshape(untrusted.shape[0], -1))
        self.cfg = cfg
        self.hit_threshold = cfg.mask_hit_threshold
        self.count_rule = cfg.mask_count_rule  # code (official release) | ours
        self.normalisation = cfg.mask_normalisation  # code | ours
        self.renormalise = cfg.mask_renormalise
        self.source_choice = cfg.mask_source_choice  # random (official release) | nearest
        erode = cfg.mask_erode_px
        self._sums: dict[str, float] = {}
        self._steps = 0
        scene, views = trainer.scene, trainer.views
        V, H, W = instance_ids.shape
        self.H, self.W = H, W
        self.members = torch.from_numpy(eroded_instances(instance_ids, erode)).reshape(V, -1)  # the rays each instance warps
        self.images = torch.from_numpy(np.ascontiguousarray(scene.images[views].transpose(0, 3, 1, 2)).astype(np.float32))
        self.ids_img = torch.from_numpy(instance_ids.astype(np.int64))
        rays = trainer.rays
        self.scale = rays.scale
        from methods.monosdf.rays import normalisation

        self.centre = torch.from_numpy(normalisation(scene)[0].astype(np.float32))
        self.K = torch.from_numpy(scene.intrinsics[views].astype(np.float32))
        self.w2c = torch.from_numpy(np.linalg.inv(scene.cam_to_world[views]).astype(np.float32))
        min_area = cfg.mask_min_area_frac * H * W
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
        self.n_source = cfg.mask_n_source
        self.candidates: dict[tuple[int, int], list[int]] = {}  # (view, instance) -> every valid source view, nearest first
        self.sources: dict[tuple[int, int], list[int]] = {}  # ... the n_source nearest (``mask_source_choice: nearest``)
        lo, hi = np.deg2rad(cfg.mask_min_angle_deg), np.deg2rad(cfg.mask_max_angle_deg)
        for k, per_view in centres.items():
            if len(per_view) < cfg.mask_min_views:
                continue
            for v, d in per_view.items():
                cands = []
                for j, dj in per_view.items():
                    if j == v:
                        continue
                    ang = np.arccos(np.clip(d @ dj, -1.0, 1.0))
                    dist = _ray_distance(origins[v], d, origins[j], dj)
                    if lo < ang < hi and dist < cfg.mask_max_ray_dist:
                        cands.append((dist, j))
                if cands:
                    self.candidates[(v, k)] = [j for _, j in sorted(cands)]
                    self.sources[(v, k)] = self.candidates[(v, k)][: self.n_source]
        self.instances_of_view: dict[int, list[int]] = {}  # view -> its valid instances (those with source views)
        for v, k in sorted(self.sources):
            self.instances_of_view.setdefault(v, []).append(k)

    def __call__(self, trainer: Any, view: int, pixels: torch.Tensor, out: RenderOutput) -> dict[str, tuple[float, torch.Tensor]]:
        ids = self.members[view, pixels]
        untrusted = self.untrusted[view, pixels]
        code_norm = self.normalisation == "code"
        valid_instances = self.instances_of_view.get(view, [])
        per_instance: list[torch.Tensor] = []
        stats = {"untrusted_rays": float(untrusted.sum()), "rays": 0.0, "instances": 0.0,
                 "instances_valid": float(len(valid_instances)), "wvalid_sum": 0.0, "gap_sum": 0.0}
        for k in valid_instances:
            sel = torch.nonzero(untrusted & (ids == k))[:, 0]
            if len(sel) == 0:
                continue  # code: still counts in the denominator (instances_valid)
            srcs = self._choose_sources(view, k, trainer.gen)
            o = trainer.rays.origins[view]
            d = trainer.rays.dirs[view, pixels[sel]]
            pts = (o[None, None, :] + d[:, None, :] * out.t[sel][..., None]) * self.scale + self.centre  # world (r, S, 3)
            w = out.weights[sel]  # (r, S), differentiable
            ref = trainer.rgb[view, pixels[sel]]  # (r, 3)
            per_source: list[torch.Tensor] = []
            counted_any = False
            for j in srcs:
                pc = pts @ self.w2c[j, :3, :3].T + self.w2c[j, :3, 3]
                z = pc[..., 2].clamp_min(1e-6)
                u = self.K[j, 0, 0] * pc[..., 0] / z + self.K[j, 0, 2]
                v = self.K[j, 1, 1] * pc[..., 1] / z + self.K[j, 1, 2]
                inside = (pc[..., 2] > 1e-6) & (u >= 0) & (u <= self.W - 1) & (v >= 0) & (v <= self.H - 1)
                grid = torch.stack([u / (self.W - 1) * 2 - 1, v / (self.H - 1) * 2 - 1], -1).reshape(1, -1, 1, 2)
                src = torch.cat([self.images[j], (self.ids_img[j] == k).float()[None]], 0)[None]  # (1, 4, H, W)
                samp = F.grid_sample(src, grid, mode="bilinear", align_corners=True).reshape(4, *u.shape)  # (4, r, S)
                in_mask = samp[3] > self.hit_threshold
                valid = (inside & in_mask).float()
                wv = w * valid
                warped = (wv[..., None] * samp[:3].permute(1, 2, 0)).sum(1)  # (r, 3)
                if self.renormalise:  # DIAGNOSTIC: the warped colour without the darkening of sum(w valid) < 1
                    warped = warped / wv.sum(-1, keepdim=True).clamp_min(1e-6)
                if self.count_rule == "code":
                    count = ((w * inside.float()).sum(-1) > 0.01) & (in_mask.sum(-1) > 0)
                else:
                    count = (wv.sum(-1) > 0.01) & (valid.sum(-1) > 0)
                l1 = (warped - ref).abs().mean(-1)  # (r,) mean over the channels (code)
                if count.any():
                    counted_any = True
                    with torch.no_grad():
                        stats["rays"] += float(count.sum())
                        stats["wvalid_sum"] += float(wv.sum(-1)[count].sum())
                        stats["gap_sum"] += float((ref - warped).mean(-1)[count].sum())
                if code_norm:
                    cnt = count.float()
                    per_source.append((l1 * cnt).sum() / (cnt.sum() + 1e-6))
                elif count.any():
                    per_source.append(l1[count].mean())
            stats["instances"] += float(counted_any)
            if per_source:
                per_instance.append(torch.stack(per_source).mean())
        self._accumulate(stats)
        if not per_instance:
            return {"mask": (self.weight, torch.zeros(()))}
        if code_norm:
            return {"mask": (self.weight, torch.stack(per_instance).sum() / (len(valid_instances) + 1e-6))}
        return {"mask": (self.weight, torch.stack(per_instance).mean())}

    def _choose_sources(self, view: int, k: int, gen: torch.Generator) -> list[int]:
        """``nearest``: the fixed ``n_source`` nearest views. ``random`` (code): ``n_source`` of the valid views
        drawn at random every step, without replacement when there are enough, else with."""
        if self.source_choice == "nearest":
            return self.sources[(view, k)]
        cands = self.candidates[(view, k)]
        if len(cands) >= self.n_source:
            pick = torch.randperm(len(cands), generator=gen)[: self.n_source]
        else:
            pick = torch.randint(0, len(cands), (self.n_source,), generator=gen)
        return [cands[int(i)] for i in pick]

    def _accumulate(self, stats: dict[str, float]) -> None:
        for key, val in stats.items():
            self._sums[key] = self._sums.get(key, 0.0) + val
        self._steps += 1

    def diagnostics(self) -> dict[str, float]:
        """The module docstring's diagnostics, averaged over the steps since the last call (then reset);
        empty before the first step."""
        if self._steps == 0:
            return {}
        n, s = self._steps, self._sums
        out = {f"mask_{k}": s[k] / n for k in ("untrusted_rays", "rays", "instances", "instances_valid")}
        if s["rays"] > 0:
            out["mask_wvalid_mean"] = s["wvalid_sum"] / s["rays"]
            out["mask_color_gap"] = s["gap_sum"] / s["rays"]
        self._sums, self._steps = {}, 0
        return out
