"""Nearest-neighbour distances between point clouds: a fast path and its brute-force twin.

The default is open3d's float64 ``NearestNeighborSearch`` (a KD-tree, exact). It was chosen by
measurement on this machine (``benchmarks/bench_mesh_metrics.py --threads 1``, 2 x 200k points, both
directions + N.C., both in Z-order): 0.47 s vs scipy's ``cKDTree`` 0.57 s when the prediction lies on
the GT, 1.12 vs 2.59 s when half of it is floaters far from any GT point, which is what an unconverged
or prior-free SDF produces and what dominates a table's evaluation time. ``backend="scipy"``
stays available (matches the brute-force twin to 1e-12, as does open3d); ``backend="brute"`` is the
obviously-correct reference used by the tests (O(N M) in chunks, only for small clouds).

Both KD-tree backends see the points in Z-order (:func:`morton_order`: queries and reference sorted
along a Morton curve, the results mapped back to the caller's order). A mesh's surface samples come in
face order and its vertices in marching-cubes order, so consecutive queries jump across the scene and
every query walks the tree from a cold cache; in Z-order consecutive queries visit the same nodes.
Exact (same distances; the index of the nearest point can differ only between equidistant points) and
measured 1.5-3x faster per direction at one thread on the dense table's meshes (docs/performance.md).
"""

from __future__ import annotations

import os
from typing import Any, Literal

import numpy as np

from metrics._checks import as_points, check_int

Backend = Literal["scipy", "open3d", "brute"]
MORTON_BITS = 10  # per axis: 1024^3 cells over the cloud's bounding cube


def _spread_bits(x: np.ndarray) -> np.ndarray:
    """Interleave two zero bits after each of the low 10 bits of ``x`` (uint64): b9..b0 -> b9 0 0 ... b0."""
    x = x & np.uint64(0x3FF)
    x = (x | (x << np.uint64(16))) & np.uint64(0x30000FF)
    x = (x | (x << np.uint64(8))) & np.uint64(0x300F00F)
    x = (x | (x << np.uint64(4))) & np.uint64(0x30C30C3)
    x = (x | (x << np.uint64(2))) & np.uint64(0x9249249)
    return x


def morton_order(points: np.ndarray) -> np.ndarray:
    """Permutation that sorts (N, 3) points along a Z-order (Morton) curve over their bounding cube
    (``MORTON_BITS`` bits per axis; stable, so equal codes keep their order). (N,) int64."""
    p = np.asarray(points, dtype=np.float64)
    lo = p.min(axis=0)
    span = float((p.max(axis=0) - lo).max())
    scale = (2**MORTON_BITS - 1) / span if span > 0 else 0.0
    c = ((p - lo) * scale).astype(np.uint64)
    code = _spread_bits(c[:, 0]) | (_spread_bits(c[:, 1]) << np.uint64(1)) | (_spread_bits(c[:, 2]) << np.uint64(2))
    return np.argsort(code, kind="stable")


def nearest_neighbor_bruteforce(
    query: Any, reference: Any, chunk: int = 2048
) -> tuple[np.ndarray, np.ndarray]:
    """Exact nearest neighbours by exhaustive search (the reference twin of :func:`nearest_neighbor`).

    Args:
        query: (M, 3) points (numpy or torch, any real dtype), any unit (distances come out in it).
        reference: (N, 3) points, same unit.
        chunk: number of query points processed at once (memory is ``chunk * N`` floats).

    Returns:
        distances (M,) float64 Euclidean distance from each query point to its nearest reference point,
        indices (M,) int64 index into ``reference`` (lowest index on exact ties).
    """
    q = as_points(query, "query")
    r = as_points(reference, "reference")
    chunk = check_int(chunk, "chunk")
    dist = np.empty(q.shape[0], dtype=np.float64)
    idx = np.empty(q.shape[0], dtype=np.int64)
    for s in range(0, q.shape[0], chunk):
        d2 = ((q[s : s + chunk, None, :] - r[None, :, :]) ** 2).sum(-1)  # [c, N]
        j = np.argmin(d2, axis=1)
        idx[s : s + chunk] = j
        dist[s : s + chunk] = np.sqrt(d2[np.arange(j.shape[0]), j])
    return dist, idx


def nearest_neighbor(
    query: Any, reference: Any, backend: Backend = "open3d", workers: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Distance from every query point to its nearest reference point.

    .. math:: d_i = \\min_j \\lVert q_i - r_j \\rVert_2

    Args:
        query: (M, 3) points (numpy or torch; float32 / float64 / int), finite, M >= 1.
        reference: (N, 3) points in the same unit, finite, N >= 1.
        backend: ``"open3d"`` (float64 open3d.core NNS, default), ``"scipy"`` (cKDTree) or ``"brute"``.
        workers: threads for the scipy query (-1 = all cores; None = ``OMP_NUM_THREADS`` when set, as in a
            ``bench run`` worker, else all cores). open3d follows ``open3d.utility.set_max_threads``.

    Returns:
        distances (M,) float64 in the unit of the inputs, indices (M,) int64 into ``reference``.

    Raises:
        TypeError: inputs are not arrays / tensors. ValueError: wrong shape, empty, NaN/inf, bad backend.

    Example:
        >>> d, i = nearest_neighbor(np.zeros((1, 3)), np.array([[0., 0., 2.], [0., 1., 0.]]))
        >>> float(d[0]), int(i[0])
        (1.0, 1)
    """
    q = as_points(query, "query")
    r = as_points(reference, "reference")
    if backend in ("scipy", "open3d"):
        return NearestNeighborIndex(r, backend, workers).query(q)
    if backend == "brute":
        return nearest_neighbor_bruteforce(q, r)
    raise ValueError(f"backend must be 'scipy', 'open3d' or 'brute', got {backend!r}")


class NearestNeighborIndex:
    """A reference cloud prepared once for many nearest-neighbour queries (a GT cloud evaluated against
    every snapshot of a job): its Z-order and its KD-tree. ``query`` is :func:`nearest_neighbor`.

    Args:
        reference: (N, 3) points, finite, N >= 1. backend: ``"open3d"`` or ``"scipy"``.
        workers: scipy query threads (see :func:`nearest_neighbor`).

    Attributes:
        points: (N, 3) float64 reference as given; order: (N,) int64 its Z-order; sorted_points:
        (N, 3) float64 ``points[order]``.
    """

    def __init__(self, reference: Any, backend: Backend = "open3d", workers: int | None = None) -> None:
        if backend not in ("scipy", "open3d"):
            raise ValueError(f"NearestNeighborIndex backend must be 'scipy' or 'open3d', got {backend!r}")
        r = as_points(reference, "reference")
        self.backend = backend
        self.workers = workers
        self.points = r
        self.order = morton_order(r)
        self.sorted_points = np.ascontiguousarray(r[self.order])
        if backend == "scipy":
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.sorted_points, balanced_tree=False, compact_nodes=False)
        else:
            import open3d as o3d

            self._tree = o3d.core.nns.NearestNeighborSearch(o3d.core.Tensor(self.sorted_points))
            self._tree.knn_index()

    def __len__(self) -> int:
        return int(self.order.shape[0])

    def query_sorted(self, q_sorted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Nearest reference point of each row of ``q_sorted`` (M, 3) float64, best in Z-order: distances
        (M,) float64 and indices (M,) int64 into the ORIGINAL reference, in the order of ``q_sorted``."""
        if self.backend == "scipy":
            workers = self.workers if self.workers is not None else int(os.environ.get("OMP_NUM_THREADS", "-1") or -1)
            d, i = self._tree.query(q_sorted, k=1, workers=workers)
            d, i = np.asarray(d, dtype=np.float64), np.asarray(i, dtype=np.int64)
        else:
            import open3d as o3d

            i, d2 = self._tree.knn_search(o3d.core.Tensor(np.ascontiguousarray(q_sorted, dtype=np.float64)), 1)
            d, i = np.sqrt(d2.numpy()[:, 0]).astype(np.float64), i.numpy()[:, 0].astype(np.int64)
        return d, self.order[i]

    def query(self, query: Any) -> tuple[np.ndarray, np.ndarray]:
        """:func:`nearest_neighbor` of ``query`` (M, 3) against this reference: (M,) distances, (M,) indices."""
        q = as_points(query, "query")
        qo = morton_order(q)
        d_sorted, i_sorted = self.query_sorted(np.ascontiguousarray(q[qo]))
        return _unsort(qo, d_sorted, i_sorted)

    def query_from(self, other: "NearestNeighborIndex") -> tuple[np.ndarray, np.ndarray]:
        """Nearest neighbours of ``other``'s points (their Z-order is reused), in ``other``'s original order."""
        d_sorted, i_sorted = self.query_sorted(other.sorted_points)
        return _unsort(other.order, d_sorted, i_sorted)


def _unsort(order: np.ndarray, d_sorted: np.ndarray, i_sorted: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    dist = np.empty_like(d_sorted)
    idx = np.empty_like(i_sorted)
    dist[order] = d_sorted
    idx[order] = i_sorted
    return dist, idx
