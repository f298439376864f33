"""Uncertainty-guided ray sampling (paper Sec. 3.4; official ``datasets/scene_dataset.py``).

Per step and view: a fraction ``fg_fraction`` (3/4; ``fg_fraction_dense`` = 95 % when instances cover
more than ``dense_coverage`` = 70 % of the image) of the rays go to foreground instances; each
instance's share is proportional to its area; inside an instance pixels are drawn with probability
proportional to ``U + prob_offset`` (0.05), with replacement. The remaining rays are uniform over
background pixels outside the instance masks dilated by ``bg_dilation_px``.
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.ndimage import binary_dilation


class GuidedSampler:
    """``sampler(view, n, generator) -> (n,) flat pixel indices`` for the training views.

    Args:
        instance_ids: (V, H, W) int multi-view-consistent ids of the training views (0 = none).
        is_background: id -> background flag (background ids are not "foreground instances").
        uncertainty: (V, H, W) U in [0, 1].
    """

    def __init__(self, instance_ids: np.ndarray, is_background: dict[int, bool], uncertainty: np.ndarray,
                 fg_fraction: float = 0.75, fg_fraction_dense: float = 0.95, dense_coverage: float = 0.7,
                 prob_offset: float = 0.05, bg_dilation_px: int = 2) -> None:
        V, H, W = instance_ids.shape
        self.hw = H * W
        self.views: list[dict] = []
        for v in range(V):
            ids = instance_ids[v].reshape(-1)
            fg = np.array([i != 0 and not is_background.get(int(i), False) for i in np.unique(ids)])
            fg_ids = np.unique(ids)[fg]
            fg_mask = np.isin(ids, fg_ids)
            inst = []
            for i in fg_ids:
                pix = np.flatnonzero(ids == i)
                prob = uncertainty[v].reshape(-1)[pix].astype(np.float64) + prob_offset
                inst.append((torch.from_numpy(pix), torch.from_numpy(prob / prob.sum()), len(pix)))
            dil = binary_dilation(fg_mask.reshape(H, W), iterations=bg_dilation_px) if bg_dilation_px > 0 else fg_mask.reshape(H, W)
            bg = np.flatnonzero(~dil.reshape(-1))
            coverage = fg_mask.mean()
            frac = fg_fraction_dense if coverage > dense_coverage else fg_fraction
            self.views.append({"instances": inst, "bg": torch.from_numpy(bg), "frac": frac if inst else 0.0})

    def __call__(self, view: int, n: int, gen: torch.Generator) -> torch.Tensor:
        info = self.views[view]
        n_fg = int(round(info["frac"] * n)) if len(info["bg"]) else n
        if not info["instances"]:
            n_fg = 0
        out = []
        if n_fg:
            areas = torch.tensor([a for _, _, a in info["instances"]], dtype=torch.float64)
            counts = torch.floor(areas / areas.sum() * n_fg).long()
            rest = n_fg - int(counts.sum())
            if rest > 0:  # remainder by area, deterministic given the generator
                counts += torch.bincount(torch.multinomial(areas, rest, replacement=True, generator=gen), minlength=len(areas))
            for (pix, prob, _), k in zip(info["instances"], counts.tolist()):
                if k:
                    out.append(pix[torch.multinomial(prob, k, replacement=True, generator=gen)])
        n_bg = n - n_fg
        if n_bg:
            bg = info["bg"] if len(info["bg"]) else torch.arange(self.hw)
            out.append(bg[torch.randint(0, len(bg), (n_bg,), generator=gen)])
        return torch.cat(out)
