"""Per-job artifacts: what a researcher opens after a run, beside the numbers.

``<out>/<scale>/artifacts/<job_id>/`` holds, when the method produced them:

* ``mesh.ply``: the final snapshot's mesh (binary PLY, world metres);
* ``uncertainty.npy`` (float16, (N, H, W), 0 = certain .. 1 = most uncertain) and ``uncertainty.png``
  (the first views' maps beside their images): MonoInstance's per-view density uncertainty;
* ``renders.npy`` (float16, (M, H, W, 3) in [0, 1]) and ``renders.png``: the final snapshot's test-view
  renders (view-synthesis methods, e.g. LLFF); ``depths.npy`` (float16, (M, H, W) z-depth in metres, 0 =
  not covered) when the method renders depth.

The folder is written to a hidden temporary beside it and renamed into place, so it is complete or
absent (a killed job leaves no half-written artifacts). Size at the small scale: a room mesh at
marching-cubes resolution 128 is 2-5 MB, the uncertainty maps 0.6 MB; the budget a job may write is
:data:`BUDGET_MB` (larger meshes are decimated to fit, with a note in ``README.txt``).
"""

from __future__ import annotations

import io
import os
import shutil
import uuid
from pathlib import Path
from typing import Any, cast

import numpy as np

from bench.figures import grid_png

BUDGET_MB = 8.0
PREVIEW_VIEWS = 4


def artifact_dir(root: Path, job_id: str) -> Path:
    return Path(root) / job_id


def _mesh_bytes(mesh: Any, budget_bytes: float) -> tuple[bytes, str]:
    """Binary PLY of ``mesh``; decimated (quadric, open3d) until it fits ``budget_bytes``."""
    data = mesh.export(file_type="ply", encoding="binary")
    if len(data) <= budget_bytes:
        return data, ""
    import open3d as o3d
    import trimesh

    m = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.asarray(mesh.vertices)), o3d.utility.Vector3iVector(np.asarray(mesh.faces)))
    target = max(1000, int(len(mesh.faces) * budget_bytes / len(data) * 0.9))
    m = m.simplify_quadric_decimation(target)
    small = trimesh.Trimesh(np.asarray(m.vertices), np.asarray(m.triangles), process=False)
    note = f"mesh.ply decimated from {len(mesh.faces)} to {len(small.faces)} faces to fit the {budget_bytes / 1e6:.1f} MB budget\n"
    return cast(bytes, small.export(file_type="ply", encoding="binary")), note


def write_job_artifacts(artifacts: Any, scene: Any, folder: Path, budget_mb: float = BUDGET_MB) -> list[str]:
    """Write ``artifacts`` (a :class:`methods.base.Artifacts`) of a job on ``scene`` into ``folder``,
    all-or-nothing. Returns the file names written (empty: the method produced nothing to keep)."""
    folder = Path(folder)
    files: dict[str, bytes] = {}
    notes = ""
    final = artifacts.snapshots[-1] if artifacts.snapshots else None
    budget = budget_mb * 1e6
    if artifacts.uncertainty is not None:
        unc = np.asarray(artifacts.uncertainty, dtype=np.float16)
        buf = io.BytesIO()
        np.save(buf, unc, allow_pickle=False)
        files["uncertainty.npy"] = buf.getvalue()
        k = min(PREVIEW_VIEWS, len(unc))
        views = np.linspace(0, len(unc) - 1, k).round().astype(int)
        img_views = views if len(unc) == scene.num_views else np.arange(k)
        files["uncertainty.png"] = grid_png(
            [[(scene.images[i], f"image {i}", {}) for i in img_views],
             [(unc[i].astype(np.float32), f"uncertainty {i}", {"cmap": "inferno", "vmin": 0, "vmax": 1}) for i in views]])
    if final is not None and final.renders is not None and len(final.renders):
        r = np.clip(np.asarray(final.renders, dtype=np.float32), 0, 1)
        k = min(PREVIEW_VIEWS, len(r))
        files["renders.png"] = grid_png([[(r[i], f"test render {i}", {}) for i in range(k)]])
        buf = io.BytesIO()
        np.save(buf, r.astype(np.float16), allow_pickle=False)
        files["renders.npy"] = buf.getvalue()
        if final.depths is not None:
            buf = io.BytesIO()
            np.save(buf, np.asarray(final.depths, dtype=np.float16), allow_pickle=False)
            files["depths.npy"] = buf.getvalue()
    if final is not None and final.mesh is not None and len(getattr(final.mesh, "faces", [])):
        left = budget - sum(len(b) for b in files.values())
        files["mesh.ply"], notes = _mesh_bytes(final.mesh, max(left, 0.25 * budget))
    if not files:
        return []
    if notes:
        files["README.txt"] = notes.encode()
    tmp = folder.parent / f".{folder.name}.{uuid.uuid4().hex[:8]}.tmp"
    tmp.mkdir(parents=True)
    try:
        for name, data in files.items():
            (tmp / name).write_bytes(data)
        if folder.exists():
            shutil.rmtree(folder)
        os.replace(tmp, folder)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return sorted(files)
