"""Per-view instance segmentation as a single-image segmenter would give it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from bench.data.scene import Scene

from ._params import param
from .registry import register


@dataclass(frozen=True)
class SegmentationParams:
    permute_ids: bool = param(
        True, "bool", doc="relabel each view's segments 1..n in a random order (ids not consistent across views)"
    )
    split_prob: float = param(
        0.0, "float", lo=0.0, hi=1.0, unit="1", doc="per view and segment: split in two by a random line"
    )
    merge_prob: float = param(
        0.0, "float", lo=0.0, hi=1.0, unit="1", doc="per view and segment: merge with an adjacent segment"
    )
    miss_prob: float = param(0.0, "float", lo=0.0, hi=1.0, unit="1", doc="per view and segment: drop (id 0)")
    min_area_px: int = param(0, "int", lo=0, unit="px", doc="segments smaller than this become 0")


def _background_of(scene: Scene, v: int, seg: np.ndarray) -> dict[int, bool]:
    """Background flag per segment id of view v: seg_background if known, else the GT instance table."""
    known = scene.seg_background[v] if scene.seg_background is not None else {}
    out = {}
    for sid in np.unique(seg):
        sid = int(sid)
        if sid == 0:
            continue
        if sid in known:
            out[sid] = bool(known[sid])
        elif sid in scene.instances:
            out[sid] = bool(scene.instances[sid].is_background)
        else:
            out[sid] = False
    return out


def _adjacent_pairs(seg: np.ndarray) -> set[tuple[int, int]]:
    """Unordered pairs of distinct non-zero ids that touch (4-neighbourhood)."""
    pairs = set()
    for a, b in ((seg[:, :-1], seg[:, 1:]), (seg[:-1], seg[1:])):
        m = (a != b) & (a > 0) & (b > 0)
        for x, y in zip(a[m].tolist(), b[m].tolist()):
            pairs.add((min(x, y), max(x, y)))
    return pairs


@register("segmentation_inconsistent", SegmentationParams, needs=("seg_masks",))
def segmentation_inconsistent(scene: Scene, p: SegmentationParams, rng: np.random.Generator) -> dict[str, Any]:
    """Per-view segmentation errors of a single-image instance segmenter.

    Models: masks predicted independently per image (the paper uses an entity segmenter per view and
    then clusters masks across views): ids are arbitrary per view, objects are sometimes cut in two
    (over-segmentation), glued to a neighbour (under-segmentation), missed, or too small to keep.

    Per view, in this order: (1) each segment is dropped (-> 0) with ``miss_prob``; (2) in increasing
    id order, each segment not yet merged is, with ``merge_prob``, merged with a random adjacent
    (4-neighbour) segment not yet merged -- the merged segment is background only if both were;
    (3) each segment is, with ``split_prob``, split in two by a line through a random pixel of it at a
    random angle (both halves keep its background flag; skipped if one side would be empty);
    (4) segments smaller than ``min_area_px`` pixels become 0; (5) with ``permute_ids`` the surviving
    segments are relabelled 1..n in a random order (else ids are kept, new halves take max id + 1).
    ``seg_background[v]`` is rebuilt for the final ids. GT instance ids are untouched.

    Parameters: permute_ids (bool), split_prob, merge_prob, miss_prob (probabilities), min_area_px
    (pixels).
    """
    seg_all = cast(np.ndarray, scene.seg_masks)  # rendered by the synthesiser before any effect runs
    n_views, h, w = seg_all.shape
    new_bg: list[dict[int, bool]] = []
    counts: dict[str, list[int]] = {"missed": [], "merged": [], "split": [], "too_small": []}
    yy, xx = np.mgrid[0:h, 0:w]
    for v in range(n_views):
        seg = seg_all[v].astype(np.int64)
        bg = _background_of(scene, v, seg)
        ids = sorted(bg)
        # (1) missed instances
        missed = 0
        if p.miss_prob > 0:
            for sid in ids:
                if rng.random() < p.miss_prob:
                    seg[seg == sid] = 0
                    del bg[sid]
                    missed += 1
        # (2) under-segmentation: merge pairs of adjacent segments
        merged = 0
        if p.merge_prob > 0:
            pairs = _adjacent_pairs(seg)
            done: set[int] = set()
            for sid in sorted(bg):
                if sid in done or rng.random() >= p.merge_prob:
                    continue
                nbrs = sorted({b if a == sid else a for a, b in pairs if sid in (a, b)} - done - {sid})
                nbrs = [n for n in nbrs if n in bg]
                if not nbrs:
                    continue
                other = nbrs[int(rng.integers(len(nbrs)))]
                seg[seg == other] = sid
                other_bg = bg.pop(other)
                bg[sid] = bg[sid] and other_bg
                done.update((sid, other))
                merged += 1
        # (3) over-segmentation: split by a random line through the segment
        split = 0
        if p.split_prob > 0:
            next_id = max(bg, default=0) + 1
            for sid in sorted(bg):
                if rng.random() >= p.split_prob:
                    continue
                m = seg == sid
                py, px = yy[m], xx[m]
                k = int(rng.integers(len(py)))
                th = rng.uniform(0.0, np.pi)
                side = (px - px[k]) * np.cos(th) + (py - py[k]) * np.sin(th) > 0
                if side.all() or not side.any():
                    continue
                seg[py[side], px[side]] = next_id
                bg[next_id] = bg[sid]
                next_id += 1
                split += 1
        # (4) min-area filtering
        small = 0
        if p.min_area_px > 0:
            for sid in sorted(bg):
                if int((seg == sid).sum()) < p.min_area_px:
                    seg[seg == sid] = 0
                    del bg[sid]
                    small += 1
        # (5) relabel
        present = sorted(bg)
        if p.permute_ids and present:
            labels = rng.permutation(len(present)) + 1
            lut = np.zeros(int(seg.max()) + 1, dtype=np.int64)
            lut[present] = labels
            seg = lut[seg]
            bg = {int(lbl): bg[old] for old, lbl in zip(present, labels.tolist())}
        seg_all[v] = seg.astype(seg_all.dtype)
        new_bg.append({int(k): bool(bg[k]) for k in sorted(bg)})
        counts["missed"].append(missed)
        counts["merged"].append(merged)
        counts["split"].append(split)
        counts["too_small"].append(small)
    scene.seg_background = new_bg
    return counts
