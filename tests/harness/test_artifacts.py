"""Per-job artifacts (bench.artifacts): what is written, all-or-nothing, the size budget."""

from __future__ import annotations

import numpy as np
import trimesh

from bench.artifacts import write_job_artifacts
from methods.base import Artifacts, Snapshot


class _Scene:
    num_views = 3
    images = np.random.default_rng(0).random((3, 12, 16, 3)).astype(np.float32)


def test_mesh_uncertainty_and_renders_are_written_and_readable(tmp_path):
    mesh = trimesh.creation.icosphere(2)
    unc = np.random.default_rng(1).random((3, 12, 16)).astype(np.float32)
    snap = Snapshot(1.0, 10, 1.0, mesh=mesh, renders=np.zeros((2, 12, 16, 3), np.float32), depths=np.ones((2, 12, 16), np.float32))
    files = write_job_artifacts(Artifacts([snap], uncertainty=unc), _Scene(), tmp_path / "job")
    assert files == ["depths.npy", "mesh.ply", "renders.npy", "renders.png", "uncertainty.npy", "uncertainty.png"]
    back = trimesh.load(tmp_path / "job" / "mesh.ply", process=False)
    assert len(back.faces) == len(mesh.faces)
    np.testing.assert_allclose(np.load(tmp_path / "job" / "uncertainty.npy"), unc, atol=1e-3)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary left


def test_nothing_to_keep_writes_nothing_and_a_big_mesh_is_decimated_to_the_budget(tmp_path):
    assert write_job_artifacts(Artifacts([Snapshot(1.0, 1, 0.0)]), _Scene(), tmp_path / "none") == []
    assert not (tmp_path / "none").exists()
    big = trimesh.creation.icosphere(6)  # 82k faces, ~1.6 MB
    files = write_job_artifacts(Artifacts([Snapshot(1.0, 1, 0.0, mesh=big)]), _Scene(), tmp_path / "big", budget_mb=0.5)
    assert files == ["README.txt", "mesh.ply"] and (tmp_path / "big" / "mesh.ply").stat().st_size <= 0.5e6
    assert "decimated" in (tmp_path / "big" / "README.txt").read_text()
