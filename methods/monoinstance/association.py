"""Step "multi-view consistent segmentation" of MonoInstance (paper Sec. 3.2, MaskClustering-inspired).

Per-view segments (``Scene.seg_masks``: ids local to each view) are associated into global instances:

1. **Nodes**: every (view, segment) with at least ``assoc_min_pixels`` pixels of valid aligned depth.
   Smaller segments get global id 0 ("none").
2. **Clouds**: each node's pixels are back-projected with the aligned metric depth (z-depth, OpenCV
   camera axes, ``cam_to_world``) to world points (metres), deterministically subsampled (evenly
   strided in raster order): at most ``assoc_max_points`` query points, and a denser copy of at most
   ``assoc_max_target_points`` that the other node's query points are measured against (so the
   overlap radius does not have to exceed the spacing of a sparse subsample on large walls).
3. **Edges** between nodes of *different views* with the *same background flag* (foreground never links
   to background), whose bounding boxes (grown by the threshold) intersect, when both hold:

   * Chamfer distance below ``assoc_chamfer_m`` metres (or, if ``assoc_chamfer_relative`` is set,
     below that fraction of the smaller of the two clouds' bounding-box diagonals). With
     ``assoc_chamfer_mode: symmetric`` it is ``(mean_a d(a, B) + mean_b d(b, A)) / 2``; with ``min`` it is
     the smaller of the two directed means (tolerates one segment seeing only part of the other);
   * overlap: ``max(o_ab, o_ba) >= assoc_overlap_min`` where ``o_ab`` is the fraction of a's points
     within ``assoc_overlap_radius_m`` of B (one segment mostly lies on the other: MaskClustering's
     containment idea, without its view-consensus iterations).

   Edge weight = ``(o_ab + o_ba) / 2``.
4. **Clusters** (``assoc_cluster``): ``components`` (networkx connected components), ``louvain``
   (``networkx.community.louvain_communities``, weighted, seed ``assoc_seed``: resists chaining), or
   ``greedy`` (edges in decreasing weight, union-find merging two clusters only if they share no view).
5. **Same-view rule**: two segments of the same view never share a global id. For ``components`` and
   ``louvain``, a cluster holding several nodes of one view keeps the one with the largest summed edge
   weight into the cluster (ties: more pixels, then smaller segment id); the others become their own
   instances (counted in ``n_same_view_splits``).
6. **Ids**: clusters are numbered 1.. in the order of their first node (view, then local id), so the
   result is deterministic. ``is_background[g]`` is the pixel-weighted majority of the nodes' flags
   (``Scene.seg_background``, the stand-in for the text-prompted detector).

``assoc_background: mark`` leaves background segments out of the graph: each becomes its own
instance flagged background (their uncertainty is 0 either way).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from methods.monoinstance.config import UncertaintyStageConfig, load_stage_config
from metrics.camera import backproject_pixels


@dataclass
class Association:
    """Result of :func:`associate_instances`.

    Attributes:
        global_ids: (N, H, W) int32 instance ids consistent across views, 0 = none.
        is_background: global id -> True for background (wall / floor / ceiling) instances.
        nodes: one row per node: ``(view, local_id, global_id, n_pixels)``.
        n_nodes, n_candidate_pairs (pairs tested), n_edges, n_clusters, n_same_view_splits.
    """

    global_ids: np.ndarray
    is_background: dict[int, bool]
    nodes: list[tuple[int, int, int, int]] = field(default_factory=list)
    n_nodes: int = 0
    n_candidate_pairs: int = 0
    n_edges: int = 0
    n_clusters: int = 0
    n_same_view_splits: int = 0

    def diagnostics(self) -> dict[str, float]:
        return {
            "n_nodes": float(self.n_nodes),
            "n_candidate_pairs": float(self.n_candidate_pairs),
            "n_edges": float(self.n_edges),
            "n_clusters": float(self.n_clusters),
            "n_same_view_splits": float(self.n_same_view_splits),
        }


def _strided(pts: np.ndarray, k: int) -> np.ndarray:
    """At most k rows of pts, evenly strided in their (raster) order: deterministic subsampling."""
    if pts.shape[0] <= k:
        return pts
    return pts[np.linspace(0, pts.shape[0] - 1, k).astype(np.int64)]


def _given_ids(seg: np.ndarray, seg_background: list[dict[int, bool]]) -> Association:
    """``assoc_cluster: given``: the per-view ids are already consistent across views (the paper's DTU
    setting: one object segmented from the background, no multi-view association). A global id is
    background when the majority of its pixels come from views that flag it so."""
    ids = [int(i) for i in np.unique(seg) if i != 0]
    votes = {i: 0 for i in ids}
    nodes = []
    for v in range(seg.shape[0]):
        for i, n_px in zip(*np.unique(seg[v][seg[v] != 0], return_counts=True)):
            nodes.append((v, int(i), int(i), int(n_px)))
            votes[int(i)] += int(n_px) if seg_background[v].get(int(i), False) else -int(n_px)
    return Association(global_ids=seg.astype(np.int32), is_background={i: votes[i] > 0 for i in ids}, nodes=nodes,
                       n_nodes=len(nodes), n_clusters=len(ids))


def associate_instances(
    seg_masks: np.ndarray,
    seg_background: list[dict[int, bool]],
    depth: np.ndarray,
    K: np.ndarray,
    cam_to_world: np.ndarray,
    config: UncertaintyStageConfig | Mapping[str, Any] | None = None,
) -> Association:
    """Associate per-view segments into multi-view consistent instances (module docstring).

    Args:
        seg_masks: (N, H, W) int per-view segment ids (0 = unsegmented), not consistent across views.
        seg_background: per view, dict local id -> True if background.
        depth: (N, H, W) aligned metric z-depth (metres, 0 = invalid).
        K: (N, 3, 3) intrinsics (pixels); cam_to_world: (N, 4, 4), OpenCV axes.
        config: the stage's config (:class:`methods.monoinstance.config.UncertaintyStageConfig`, or
            overrides of its YAML); this step reads the ``assoc_*`` keys.
            ``assoc_cluster: given`` skips the association and keeps the per-view ids (DTU).

    Returns:
        :class:`Association`. Deterministic (no randomness except Louvain's fixed seed).
    """
    from scipy.spatial import cKDTree

    cfg = load_stage_config(config)
    seg = np.asarray(seg_masks)
    dep = np.asarray(depth)
    if seg.ndim != 3 or dep.shape != seg.shape:
        raise ValueError(f"seg_masks and depth must both be (N, H, W), got {seg.shape} and {dep.shape}")
    n_views = seg.shape[0]
    if len(seg_background) != n_views:
        raise ValueError(f"seg_background has {len(seg_background)} views, expected {n_views}")
    if cfg.assoc_cluster == "given":
        return _given_ids(seg, seg_background)
    K = np.broadcast_to(np.asarray(K, dtype=np.float64), (n_views, 3, 3))
    c2w = np.asarray(cam_to_world, dtype=np.float64)

    # ---- nodes
    nodes: list[tuple[int, int, int]] = []  # (view, local id, n_pixels)
    node_bg: list[bool] = []
    clouds: list[np.ndarray] = []  # query points (<= assoc_max_points)
    targets: list[np.ndarray] = []  # denser copy the others are measured against (<= assoc_max_target_points)
    small: list[tuple[int, int]] = []
    for v in range(n_views):
        valid = np.isfinite(dep[v]) & (dep[v] > 0)
        for sid in np.unique(seg[v]):
            sid = int(sid)
            if sid == 0:
                continue
            rows, cols = np.nonzero((seg[v] == sid) & valid)
            bg = bool(seg_background[v].get(sid, False))
            if rows.size < cfg.assoc_min_pixels:
                small.append((v, sid))
                continue
            nodes.append((v, sid, int(rows.size)))
            node_bg.append(bg)
            pts = backproject_pixels(dep[v], rows, cols, K[v], c2w[v])
            targets.append(_strided(pts, cfg.assoc_max_target_points))
            clouds.append(_strided(pts, cfg.assoc_max_points))
    n = len(nodes)
    views = np.array([nd[0] for nd in nodes], dtype=np.int64)
    bgf = np.array(node_bg, dtype=bool)
    in_graph = np.ones(n, dtype=bool) if cfg.assoc_background == "associate" else ~bgf

    # ---- candidate pairs (bounding boxes grown by the largest threshold)
    edges: list[tuple[int, int, float]] = []
    n_cand = 0
    if n > 1:
        lo = np.array([c.min(0) for c in clouds])
        hi = np.array([c.max(0) for c in clouds])
        diag = np.linalg.norm(hi - lo, axis=1)
        if cfg.assoc_chamfer_relative is not None:
            thr_pair = cfg.assoc_chamfer_relative * np.minimum(diag[:, None], diag[None, :])
        else:
            thr_pair = np.full((n, n), cfg.assoc_chamfer_m)
        grow = np.maximum(thr_pair, cfg.assoc_overlap_radius_m)
        sep = np.maximum(lo[:, None, :] - hi[None, :, :], lo[None, :, :] - hi[:, None, :]).max(-1)
        cand = (
            (sep <= grow)
            & (views[:, None] != views[None, :])
            & (bgf[:, None] == bgf[None, :])
            & in_graph[:, None]
            & in_graph[None, :]
        )
        ia, ib = np.nonzero(np.triu(cand, 1))
        n_cand = int(ia.size)
        rad = cfg.assoc_overlap_radius_m
        # directed nearest distances d(a -> B) for every candidate pair, batched per target node B:
        # one KD-tree and one query call per node instead of two per pair
        # (per directed pair only two numbers are needed: the mean distance and the overlap fraction,
        # reduced per partner segment with np.add.reduceat instead of one array per pair)
        mean_d: dict[tuple[int, int], float] = {}
        overlap: dict[tuple[int, int], float] = {}
        partners: dict[int, list[int]] = {}
        for a, b in zip(ia.tolist(), ib.tolist()):
            partners.setdefault(b, []).append(a)
            partners.setdefault(a, []).append(b)
        for b in sorted(partners):
            qs = partners[b]
            d = cKDTree(targets[b]).query(np.concatenate([clouds[a] for a in qs]), k=1)[0]
            sizes = np.array([clouds[a].shape[0] for a in qs])
            starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
            means = np.add.reduceat(d, starts) / sizes
            fracs = np.add.reduceat((d <= rad).astype(np.float64), starts) / sizes
            for a, m, o in zip(qs, means.tolist(), fracs.tolist()):
                mean_d[(a, b)] = m
                overlap[(a, b)] = o
        for a, b in zip(ia.tolist(), ib.tolist()):
            mab, mba = mean_d[(a, b)], mean_d[(b, a)]
            cd = 0.5 * (mab + mba) if cfg.assoc_chamfer_mode == "symmetric" else min(mab, mba)
            oab, oba = overlap[(a, b)], overlap[(b, a)]
            if cd < thr_pair[a, b] and max(oab, oba) >= cfg.assoc_overlap_min:
                edges.append((a, b, 0.5 * (oab + oba)))

    # ---- clustering
    clusters, n_split = _cluster(n, views, edges, nodes, cfg)
    # ---- global ids
    clusters = sorted((sorted(c) for c in clusters), key=lambda c: c[0])  # node order = (view, local id)
    lut: list[dict[int, int]] = [dict() for _ in range(n_views)]
    is_bg: dict[int, bool] = {}
    table = []
    for gi, members in enumerate(clusters, start=1):
        w_bg = sum(nodes[m][2] for m in members if bgf[m])
        w_fg = sum(nodes[m][2] for m in members if not bgf[m])
        is_bg[gi] = bool(w_bg > w_fg)
        for m in members:
            v, sid, npx = nodes[m]
            lut[v][sid] = gi
            table.append((v, sid, gi, npx))
    gids = np.zeros(seg.shape, dtype=np.int32)
    for v in range(n_views):
        if not lut[v]:
            continue
        mx = int(seg[v].max())
        arr = np.zeros(mx + 1, dtype=np.int32)
        for sid, gi in lut[v].items():
            arr[sid] = gi
        s = seg[v]
        gids[v] = np.where(s > 0, arr[np.clip(s, 0, mx)], 0)
    table.sort()
    return Association(
        global_ids=gids,
        is_background=is_bg,
        nodes=table,
        n_nodes=n,
        n_candidate_pairs=n_cand,
        n_edges=len(edges),
        n_clusters=len(clusters),
        n_same_view_splits=n_split,
    )


def _cluster(n: int, views: np.ndarray, edges: list[tuple[int, int, float]], nodes, cfg) -> tuple[list[list[int]], int]:
    """Partition of range(n) into clusters with at most one node per view; returns (clusters, splits)."""
    method = cfg.assoc_cluster
    if method == "greedy":
        parent = list(range(n))
        vsets = [{int(views[i])} for i in range(n)]

        def find(x: int) -> int:
            while parent[x] != x:
                parent[x] = parent[parent[x]]
                x = parent[x]
            return x

        for a, b, _w in sorted(edges, key=lambda e: (-e[2], e[0], e[1])):
            ra, rb = find(a), find(b)
            if ra == rb or vsets[ra] & vsets[rb]:
                continue
            ra, rb = min(ra, rb), max(ra, rb)
            parent[rb] = ra
            vsets[ra] |= vsets[rb]
        groups: dict[int, list[int]] = {}
        for i in range(n):
            groups.setdefault(find(i), []).append(i)
        return list(groups.values()), 0

    import networkx as nx

    g = nx.Graph()
    g.add_nodes_from(range(n))
    g.add_weighted_edges_from(edges)
    if method == "components":
        comps = [sorted(c) for c in nx.connected_components(g)]
    else:
        comps = [
            sorted(c)
            for c in nx.community.louvain_communities(
                g, weight="weight", resolution=cfg.assoc_louvain_resolution, seed=cfg.assoc_seed
            )
        ]
    out: list[list[int]] = []
    splits = 0
    for comp in sorted(comps, key=lambda c: c[0]):
        members = set(comp)
        by_view: dict[int, list[int]] = {}
        for m in comp:
            by_view.setdefault(int(views[m]), []).append(m)
        keep = []
        for v, ms in by_view.items():
            if len(ms) == 1:
                keep.append(ms[0])
                continue

            def score(m: int) -> tuple[float, int, int]:
                w = sum(d["weight"] for _u, o, d in g.edges(m, data=True) if o in members)
                return (w, nodes[m][2], -nodes[m][1])

            best = max(ms, key=score)
            keep.append(best)
            for m in ms:
                if m != best:
                    out.append([m])
                    splits += 1
        out.append(sorted(keep))
    return out, splits
