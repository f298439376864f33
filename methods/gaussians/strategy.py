"""Densification and pruning, kept out of the renderer (gsplat's "strategy" pattern).

:class:`DefaultStrategy` follows 3DGS / gsplat's default strategy:

* after every backward pass, accumulate the norm of each visible Gaussian's screen-space mean gradient,
  in NDC units (pixel gradient x (W / 2, H / 2)), and a visibility count;
* every ``refine_every`` steps in ``[refine_start, refine_stop)``: Gaussians whose mean accumulated
  gradient exceeds ``grad_threshold`` are **cloned** (copied in place) when their largest scale is <=
  ``percent_dense x scene_extent``, else **split** (replaced by 2 samples of themselves with scales / 1.6);
  growth is capped at ``max_gaussians`` (the highest gradients win). Then Gaussians with opacity <
  ``prune_opacity`` (or, after the first opacity reset, a scale > 0.1 x extent) are **pruned**;
* every ``reset_every`` steps the opacities are reset to ``min(o, 2 x prune_opacity)``.

Parameters live in a dict of leaf tensors, each with its own Adam optimiser (so per-parameter learning
rates); resizing the parameters resizes the Adam moments too (new entries get zero moments).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import cast

import torch

from methods.gaussians.rasterize import quat_to_rotmat


@dataclass
class DefaultStrategy:
    grad_threshold: float = 0.0002
    percent_dense: float = 0.01
    refine_start: int = 100
    refine_stop: int = 1000
    refine_every: int = 100
    reset_every: int = 3000
    prune_opacity: float = 0.005
    max_gaussians: int = 20000
    scene_extent: float = 1.0
    grad2d: torch.Tensor | None = field(default=None, repr=False)
    count: torch.Tensor | None = field(default=None, repr=False)
    n_clone: int = 0
    n_split: int = 0
    n_prune: int = 0

    def step_post_backward(self, params: dict[str, torch.Tensor], optimizers: Mapping[str, torch.optim.Optimizer], step: int,
                           means2d: torch.Tensor, radii: torch.Tensor, width: int, height: int, rng: torch.Generator) -> None:
        """Update the statistics from ``means2d.grad`` (pixels) and refine on schedule (``step`` 0-based)."""
        n = params["means"].shape[0]
        if self.grad2d is None or self.grad2d.shape[0] != n:
            self.grad2d = torch.zeros(n)
            self.count = torch.zeros(n)
        if step < self.refine_stop and means2d.grad is not None:
            vis = radii > 0
            g = means2d.grad.detach() * torch.tensor([width / 2.0, height / 2.0])
            self.grad2d[vis] += g[vis].norm(dim=-1)
            cast(torch.Tensor, self.count)[vis] += 1  # set with grad2d above
        s1 = step + 1
        if self.refine_start <= s1 < self.refine_stop and s1 % self.refine_every == 0:
            self._grow(params, optimizers, rng)
            self._prune(params, optimizers, big=s1 > self.reset_every)
            self.grad2d = torch.zeros(params["means"].shape[0])
            self.count = torch.zeros(params["means"].shape[0])
        if s1 < self.refine_stop and s1 % self.reset_every == 0:
            with torch.no_grad():
                lim = math.log(2 * self.prune_opacity / (1 - 2 * self.prune_opacity))
                params["opacities"].clamp_(max=lim)
            for st in optimizers["opacities"].state.values():
                st["exp_avg"].zero_()
                st["exp_avg_sq"].zero_()

    # -------------------------------------------------------------- surgery
    @staticmethod
    def _replace(params, optimizers, new: dict[str, torch.Tensor], keep: torch.Tensor | None, n_new: int) -> None:
        """Set each parameter to ``new[name]``; Adam moments: rows ``keep`` of the old ones + ``n_new`` zero rows."""
        for name, t in new.items():
            opt = optimizers[name]
            old = params[name]
            st = opt.state.pop(old, None)
            p = t.detach().clone().requires_grad_()
            params[name] = p
            opt.param_groups[0]["params"] = [p]
            if st:
                for k in ("exp_avg", "exp_avg_sq"):
                    v = st[k][keep] if keep is not None else st[k]
                    st[k] = torch.cat([v, torch.zeros((n_new,) + v.shape[1:], dtype=v.dtype)], 0)
                opt.state[p] = st

    def _grow(self, params, optimizers, rng) -> None:
        avg = cast(torch.Tensor, self.grad2d) / cast(torch.Tensor, self.count).clamp_min(1)  # set by step_post_backward
        cand = avg > self.grad_threshold
        n = params["means"].shape[0]
        room = max(0, self.max_gaussians - n)
        with torch.no_grad():
            smax = torch.exp(params["scales"]).max(-1).values
            is_small = smax <= self.percent_dense * self.scene_extent
            clone = cand & is_small
            split = cand & ~is_small
            # cap: each clone adds 1, each split adds 1 (2 replace 1)
            nc, ns = int(clone.sum()), int(split.sum())
            if nc + ns > room:
                score = torch.where(cand, avg, torch.full_like(avg, -1.0))
                top = torch.topk(score, room).indices if room > 0 else torch.zeros(0, dtype=torch.long)
                sel = torch.zeros(n, dtype=torch.bool)
                sel[top] = True
                clone &= sel
                split &= sel
            ci = torch.nonzero(clone).squeeze(1)
            si = torch.nonzero(split).squeeze(1)
            if ci.numel() + si.numel() == 0:
                return
            # split: two samples from N(mu, Sigma), scales / 1.6; the originals are removed
            sc = torch.exp(params["scales"][si])
            R = quat_to_rotmat(params["quats"][si])
            samples = torch.randn(2, si.numel(), 3, generator=rng) * sc[None]
            new_means = (params["means"][si][None] + torch.einsum("nij,knj->kni", R, samples)).reshape(-1, 3)
            keep = torch.ones(n, dtype=torch.bool)
            keep[si] = False
            new = {}
            for name, t in params.items():
                if name == "means":
                    add_s = new_means
                elif name == "scales":
                    add_s = (params["scales"][si] - math.log(1.6)).repeat(2, *[1] * (t.dim() - 1))
                else:
                    add_s = t[si].repeat(2, *[1] * (t.dim() - 1))
                new[name] = torch.cat([t[keep], t[ci], add_s], 0)
            self._replace(params, optimizers, new, keep, ci.numel() + 2 * si.numel())
            self.n_clone += int(ci.numel())
            self.n_split += int(si.numel())

    def _prune(self, params, optimizers, big: bool) -> None:
        with torch.no_grad():
            drop = torch.sigmoid(params["opacities"]) < self.prune_opacity
            if big:
                drop |= torch.exp(params["scales"]).max(-1).values > 0.1 * self.scene_extent
            if drop.all():  # never prune everything
                drop[torch.argmax(params["opacities"])] = False
            if not drop.any():
                return
            keep = ~drop
            self._replace(params, optimizers, {k: v[keep] for k, v in params.items()}, keep, 0)
            self.n_prune += int(drop.sum())
