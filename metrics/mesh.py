"""Mesh metrics (MonoSDF / NICE-SLAM definitions) from two point sets, and seeded surface sampling.

Definitions (P = predicted points, G = GT points, d(x, S) = distance from x to its nearest point of S,
tau = threshold, default 0.05 m = 5 cm; all distances in scene units = metres):

* Accuracy     ``acc  = mean_{p in P} d(p, G)``            (lower is better)
* Completion   ``comp = mean_{g in G} d(g, P)``            (lower is better)
* Chamfer-L1   ``cd   = (acc + comp) / 2``                 (lower is better)
* Precision    ``prec = mean_{p in P} [d(p, G) < tau]``    (fraction in [0, 1], higher is better)
* Recall       ``rec  = mean_{g in G} [d(g, P) < tau]``    (fraction in [0, 1], higher is better)
* F-score      ``F = 2 prec rec / (prec + rec)``, defined as 0 when prec + rec = 0
* Normal consistency ``nc = (mean_p |n_p . n_{nn_G(p)}| + mean_g |n_g . n_{nn_P(g)}|) / 2`` in [0, 1]
  (absolute value: mesh orientation is ignored, as in MonoSDF). NaN when normals are not given.

MonoSDF's Replica script reports acc/comp in cm and ratios in %; this module returns metres and
fractions, and the table layer converts. Unlike the script (which draws a second 200k sample for N.C.),
N.C. reuses the same samples and nearest neighbours: same expectation, half the cost.

Degenerate inputs (see :func:`clean_mesh`): faces touching a NaN/inf vertex and zero-area faces are
dropped (documented, not an error); a mesh left with no face of positive area raises ValueError.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from metrics._checks import as_points, check_int, check_positive
from metrics.nn import Backend, NearestNeighborIndex, nearest_neighbor


@dataclass(frozen=True)
class MeshMetrics:
    """Reconstruction metrics of one predicted mesh against one GT mesh.

    Attributes:
        accuracy: mean pred -> GT distance, metres.
        completion: mean GT -> pred distance, metres.
        chamfer: (accuracy + completion) / 2, metres.
        precision: fraction of pred points within ``threshold`` of GT, in [0, 1].
        recall: fraction of GT points within ``threshold`` of pred, in [0, 1].
        fscore: harmonic mean of precision and recall, in [0, 1] (0 if both are 0).
        normal_consistency: in [0, 1], NaN when the protocol has no normals (ScanNet).
        threshold: the F-score threshold, metres.
        n_pred: number of predicted points used.
        n_gt: number of GT points used.
    """

    accuracy: float
    completion: float
    chamfer: float
    precision: float
    recall: float
    fscore: float
    normal_consistency: float
    threshold: float
    n_pred: int
    n_gt: int

    def as_dict(self) -> dict[str, float | int]:
        """Plain ``{name: value}`` dict (metres and fractions), JSON-serialisable."""
        return {k: (int(v) if k.startswith("n_") else float(v)) for k, v in asdict(self).items()}


def _unit(n: np.ndarray, name: str) -> np.ndarray:
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ValueError(f"{name} contains {int((norm[:, 0] < 1e-12).sum())} zero-length normals")
    return n / norm


def point_metrics(
    pred_points: Any,
    gt_points: Any,
    threshold: float = 0.05,
    pred_normals: Any | None = None,
    gt_normals: Any | None = None,
    backend: Backend = "open3d",
    gt_index: NearestNeighborIndex | None = None,
) -> MeshMetrics:
    """Accuracy, completion, Chamfer-L1, precision, recall, F-score and normal consistency.

    See the module docstring for the formulas. Invariant to point order; float32 and float64 inputs
    give the same result up to float32 rounding of the coordinates.

    Args:
        pred_points: (M, 3) predicted surface samples, metres (numpy or torch), M >= 1, finite.
        gt_points: (N, 3) GT surface samples, metres, N >= 1, finite.
        threshold: F-score distance threshold tau in metres (default 0.05 = 5 cm).
        pred_normals: optional (M, 3) normals of ``pred_points`` (normalised here; sign ignored).
        gt_normals: optional (N, 3) normals of ``gt_points``. Both or neither must be given.
        backend: nearest-neighbour backend, see :func:`metrics.nn.nearest_neighbor`.
        gt_index: optional :class:`metrics.nn.NearestNeighborIndex` of ``gt_points`` built once (a GT
            evaluated against many predictions); used when its backend is ``backend`` (otherwise the
            one-shot search runs); same results as without.

    Returns:
        :class:`MeshMetrics` (``normal_consistency`` NaN without normals).

    Raises:
        TypeError / ValueError: wrong types, shapes, empty or non-finite inputs, bad threshold.
    """
    p = as_points(pred_points, "pred_points")
    g = as_points(gt_points, "gt_points")
    tau = check_positive(threshold, "threshold")
    if (pred_normals is None) != (gt_normals is None):
        raise ValueError("give both pred_normals and gt_normals, or neither")
    pn = gn = None
    if pred_normals is not None:
        pn = _unit(as_points(pred_normals, "pred_normals"), "pred_normals")
        gn = _unit(as_points(gt_normals, "gt_normals"), "gt_normals")
        if pn.shape != p.shape:
            raise ValueError(f"pred_normals shape {pn.shape} must match pred_points shape {p.shape}")
        if gn.shape != g.shape:
            raise ValueError(f"gt_normals shape {gn.shape} must match gt_points shape {g.shape}")

    if gt_index is not None and gt_index.backend == backend:
        if len(gt_index) != g.shape[0]:
            raise ValueError(f"gt_index holds {len(gt_index)} points, gt_points {g.shape[0]}")
        d_p2g, i_p2g = gt_index.query(p)  # [M], for accuracy / precision
        d_g2p, i_g2p = NearestNeighborIndex(p, gt_index.backend).query_from(gt_index)  # [N], completion / recall
    else:
        d_p2g, i_p2g = nearest_neighbor(p, g, backend=backend)
        d_g2p, i_g2p = nearest_neighbor(g, p, backend=backend)
    acc = float(d_p2g.mean())
    comp = float(d_g2p.mean())
    prec = float((d_p2g < tau).mean())
    rec = float((d_g2p < tau).mean())
    f = 0.0 if prec + rec == 0 else 2.0 * prec * rec / (prec + rec)
    nc = float("nan")
    if pn is not None and gn is not None:  # given together (checked above)
        nc_acc = np.abs((pn * gn[i_p2g]).sum(-1)).mean()
        nc_comp = np.abs((gn * pn[i_g2p]).sum(-1)).mean()
        nc = float(0.5 * (nc_acc + nc_comp))
    return MeshMetrics(
        accuracy=acc,
        completion=comp,
        chamfer=0.5 * (acc + comp),
        precision=prec,
        recall=rec,
        fscore=float(f),
        normal_consistency=nc,
        threshold=tau,
        n_pred=int(p.shape[0]),
        n_gt=int(g.shape[0]),
    )


class EmptyReconstructionError(ValueError):
    """The predicted geometry leaves the protocol nothing to measure: an empty mesh, or no predicted point
    where the protocol evaluates (e.g. a 3-view DTU run whose few triangles lie outside the object's box).

    A result of the method (the surface was lost), not bad input: a table marks such a job failed with this
    type, and a test can tell it from a harness error by the type alone."""


def check_pred_mesh(mesh: Any, name: str = "pred_mesh") -> tuple[np.ndarray, np.ndarray]:
    """:func:`clean_mesh` for a predicted mesh: an empty one raises :class:`EmptyReconstructionError`."""
    return clean_mesh(mesh, name, empty_error=EmptyReconstructionError)


def clean_mesh(mesh: Any, name: str = "mesh", empty_error: type[ValueError] = ValueError) -> tuple[np.ndarray, np.ndarray]:
    """Validated vertices and the faces usable for sampling.

    Behaviour on degenerate input (documented, deliberate):

    * faces touching a vertex with NaN/inf coordinates are dropped;
    * faces of zero area (collinear or repeated vertices) are dropped (they carry no surface);
    * duplicated vertices / faces are kept: they do not change the area-weighted surface
      distribution except that a duplicated face is sampled twice as often (it *is* twice the area
      in the face list); unreferenced vertices are ignored.

    Args:
        mesh: ``trimesh.Trimesh`` in world metres.
        name: argument name used in error messages.
        empty_error: the ValueError type raised for a mesh without vertices or faces
            (:func:`check_pred_mesh`: :class:`EmptyReconstructionError`).

    Returns:
        vertices (V, 3) float64 (may still hold NaN rows, none referenced), faces (F, 3) int64.

    Raises:
        TypeError: not a trimesh.Trimesh. ValueError: no faces (as ``empty_error``), face index out of
        range, or no face with positive finite area left.
    """
    import trimesh

    if not isinstance(mesh, trimesh.Trimesh):
        raise TypeError(f"{name} must be a trimesh.Trimesh, got {type(mesh).__name__}")
    v = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    f = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if f.shape[0] == 0 or v.shape[0] == 0:
        raise empty_error(f"{name} is empty ({v.shape[0]} vertices, {f.shape[0]} faces)")
    if f.min() < 0 or f.max() >= v.shape[0]:
        raise ValueError(f"{name} has face indices outside [0, {v.shape[0]})")
    finite_v = np.asarray(np.isfinite(v).all(1))
    f = f[finite_v[f].all(1)]
    if f.shape[0]:
        tri = v[f]
        area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        f = f[area2 > 0]
    if f.shape[0] == 0:
        raise ValueError(f"{name} has no face with positive finite area (degenerate or NaN vertices)")
    return v, f


def sample_mesh_surface(
    mesh: Any,
    n_points: int = 200_000,
    seed: int | np.random.Generator = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample points uniformly by area on a mesh surface, with their face normals.

    Faces are drawn with probability proportional to area, then a point uniformly inside the face
    (square-root barycentric trick). Deterministic for a given ``seed`` (int or numpy Generator).
    Degenerate faces are handled by :func:`clean_mesh`.

    Args:
        mesh: ``trimesh.Trimesh`` in world metres.
        n_points: number of samples (MonoSDF's Replica protocol: 200,000).
        seed: int seed or a ``numpy.random.Generator`` (consumed).

    Returns:
        points (n_points, 3) float64 metres, normals (n_points, 3) float64 unit face normals
        (orientation from the face winding).
    """
    v, f = clean_mesh(mesh)
    n = check_int(n_points, "n_points")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(check_int(seed, "seed", 0))
    tri = v[f]  # [F, 3, 3]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])  # [F, 3]
    area2 = np.linalg.norm(cross, axis=1)
    cdf = np.cumsum(area2)
    face = np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right")
    face = np.minimum(face, f.shape[0] - 1)
    r1 = np.sqrt(rng.random(n))[:, None]
    r2 = rng.random(n)[:, None]
    t = tri[face]
    pts = (1 - r1) * t[:, 0] + r1 * (1 - r2) * t[:, 1] + r1 * r2 * t[:, 2]
    normals = cross[face] / area2[face, None]
    return pts, normals


def evaluate_mesh_pair(
    pred_mesh: Any,
    gt_mesh: Any,
    n_samples: int = 200_000,
    threshold: float = 0.05,
    seed: int = 0,
    backend: Backend = "open3d",
    gt_seed: int | None = None,
) -> MeshMetrics:
    """Sample both meshes (``n_samples`` each, seeded) and compute :func:`point_metrics` with normals.

    No culling or cropping here: that is a separate documented step (:mod:`metrics.culling`,
    :mod:`metrics.protocols`).

    Args:
        pred_mesh, gt_mesh: ``trimesh.Trimesh`` in world metres.
        n_samples: samples per mesh.
        threshold: F-score threshold, metres.
        seed: seed of the pred sampling.
        backend: nearest-neighbour backend.
        gt_seed: seed of the GT sampling, ``seed + 1`` by default (independent samples, as MonoSDF).
            Passing ``gt_seed=seed`` gives *identical* samples on meshes with the same face list
            (identical meshes -> distances exactly 0; a rigidly moved copy -> the same samples moved):
            used by the analytic tests, biased (too low) for real evaluations of congruent meshes.
    """
    s = check_int(seed, "seed", 0)
    pp, pn = sample_mesh_surface(pred_mesh, n_samples, seed=s)
    gs = s + 1 if gt_seed is None else check_int(gt_seed, "gt_seed", 0)
    gp, gn = sample_mesh_surface(gt_mesh, n_samples, seed=gs)
    return point_metrics(pp, gp, threshold, pn, gn, backend=backend)
