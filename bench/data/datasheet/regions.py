"""Per-pixel regions of a scene's views, from its ground truth (GT instance ids and GT depth).

Four regions partition the valid GT pixels (``gt_depth > 0``) of every view:

* ``thin``: thin parts of foreground objects, the project's one definition of thin-structure pixels
  (:func:`metrics.uncertainty.region_masks`, also behind ``unc_mean_thin``): pixels of a non-background
  instance that a k x k morphological opening (k = 5) of that instance's mask removes, i.e. parts
  narrower than k pixels in the image (legs, poles, stems, wires).
* ``silhouette``: the band along occlusion and instance boundaries, minus ``thin``. A *boundary pixel*
  is a pixel with a 4-neighbour of another GT instance id (0 = no surface counts as an id), or a depth
  discontinuity of the GT depth (:func:`bench.data.synth.effects.depth.depth_discontinuities`,
  threshold 0.1, the prior effects' definition); both pixels on either side of a boundary are
  boundary pixels. The band is every pixel closer than ``half_width_px`` (default 2) pixels
  (Euclidean, pixel centres) to a boundary pixel: along a straight boundary it is 2 x half_width_px
  pixels wide, half_width_px on each side of the crack between the two surfaces (with the default, the
  same band the depth-bleeding effect blurs at edge_width_px = 2).
* ``planar_background``: pixels of background instances (wall / floor / ceiling / ground) outside the band.
* ``objects``: pixels of non-background instances outside the band and not thin.

Precedence where the definitions overlap: thin > silhouette > planar_background / objects (a thin part
is always within a few pixels of its own outline, so the band would otherwise swallow it).
Besides the partition, :class:`Regions` keeps the full band (thin parts included) and the pixels of
each background category (``wall``, ``floor``, ``ceiling``) for the photometric statistics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from bench.data.errors import BenchInputError
from bench.data.scene import Scene
from bench.data.synth.effects.depth import depth_discontinuities
from metrics.uncertainty import region_masks

REGION_NAMES = ("planar_background", "objects", "thin", "silhouette")
SURFACE_CATEGORIES = ("wall", "floor", "ceiling")
BAND_HALF_WIDTH_PX = 2
EDGE_THRESHOLD = 0.1  # relative second difference of 1/z: depth_bleeding's default edge_threshold
THIN_KERNEL_PX = 5  # metrics.uncertainty.region_masks' default kernel (unc_mean_thin)


@dataclass(frozen=True)
class Regions:
    """Region masks of N views, each (N, H, W) bool.

    Attributes:
        valid: GT depth > 0 (the union of the four regions).
        planar_background, objects, thin, silhouette: the partition of ``valid`` (module docstring).
        band: the full boundary band (``silhouette`` plus the thin pixels inside it), valid pixels only.
        surfaces: category name (``wall``, ``floor``, ``ceiling``) -> valid pixels of background
            instances of that category (band included).
    """

    valid: np.ndarray
    planar_background: np.ndarray
    objects: np.ndarray
    thin: np.ndarray
    silhouette: np.ndarray
    band: np.ndarray
    surfaces: dict[str, np.ndarray]

    def partition(self) -> dict[str, np.ndarray]:
        """``{"all": valid, region name: mask}`` in ``REGION_NAMES`` order."""
        return {"all": self.valid, **{name: getattr(self, name) for name in REGION_NAMES}}

    def fractions(self) -> dict[str, float]:
        """Share of the valid GT pixels (all views pooled) in each region, in [0, 1]."""
        n = max(int(self.valid.sum()), 1)
        return {name: float(getattr(self, name).sum()) / n for name in REGION_NAMES}


def boundary_pixels(gt_instance: np.ndarray, gt_depth: np.ndarray, edge_threshold: float = EDGE_THRESHOLD) -> np.ndarray:
    """Boundary pixels of one view: a 4-neighbour with another GT instance id, or a GT depth discontinuity.

    Args:
        gt_instance: (H, W) int GT instance ids, 0 = no surface. gt_depth: (H, W) GT z-depth, metres.

    Returns:
        (H, W) bool; both pixels of a differing neighbour pair are marked.
    """
    out = depth_discontinuities(gt_depth.astype(np.float64), edge_threshold)
    dv = gt_instance[1:] != gt_instance[:-1]
    du = gt_instance[:, 1:] != gt_instance[:, :-1]
    out[1:] |= dv
    out[:-1] |= dv
    out[:, 1:] |= du
    out[:, :-1] |= du
    return out


def silhouette_band(gt_instance: np.ndarray, gt_depth: np.ndarray, half_width_px: float = BAND_HALF_WIDTH_PX) -> np.ndarray:
    """(H, W) bool: pixels closer than ``half_width_px`` (pixel-centre distance) to a boundary pixel."""
    edges = boundary_pixels(gt_instance, gt_depth)
    if not edges.any():
        return edges
    return ndimage.distance_transform_edt(~edges) < half_width_px


def compute_regions(scene: Scene, half_width_px: float = BAND_HALF_WIDTH_PX, thin_kernel_px: int = THIN_KERNEL_PX) -> Regions:
    """The regions of every view of ``scene`` (needs ``gt_depth``, ``gt_instance`` and the instance table).

    Raises:
        BenchInputError: the scene has no GT depth or GT instance ids.
    """
    if scene.gt_depth is None or scene.gt_instance is None:
        missing = "gt_depth" if scene.gt_depth is None else "gt_instance"
        raise BenchInputError(scene.root or scene.name, f"the datasheet needs GT ({missing} is absent)")
    inst = np.asarray(scene.gt_instance)
    depth = np.asarray(scene.gt_depth)
    valid = depth > 0
    bg_ids = sorted(i for i, info in scene.instances.items() if info.is_background)
    background = np.isin(inst, bg_ids) & valid
    thin = region_masks(inst, bg_ids, kernel=thin_kernel_px)["thin"] & valid
    band = np.stack([silhouette_band(inst[v], depth[v], half_width_px) for v in range(inst.shape[0])]) & valid
    surfaces = {
        cat: np.isin(inst, [i for i in bg_ids if scene.instances[i].category == cat]) & valid for cat in SURFACE_CATEGORIES
    }
    return Regions(
        valid=valid,
        planar_background=background & ~band,
        objects=valid & ~background & ~band & ~thin,
        thin=thin,
        silhouette=band & ~thin,
        band=band,
        surfaces=surfaces,
    )
