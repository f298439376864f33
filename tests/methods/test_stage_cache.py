"""``methods.stage_cache`` and MonoInstance's shared stage 1 (``share_stage1``): a job that loads the stage-1 state
another row stored ends exactly where a job that trained every step ends (the slow twin: no cache folder)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from methods.monoinstance.method import MonoInstance
from methods.registry import method_config
from methods.stage_cache import checkpoint_dir, load_stage, save_stage, stage_checkpoints, stage_key, tensor_digest

TINY = {"iterations": 16, "rays_per_batch": 64, "mesh_resolution": 24}  # stage 1 = steps 0-4; snapshots at 4, 8, 16
BASE = {"uncertainty": False, "guided_sampling": False, "mask_constraint": False}


def test_store_and_load_need_a_folder(tmp_path: Path):
    key = stage_key({"a": 1})
    assert key != stage_key({"a": 2}) and len(key) == 24
    assert checkpoint_dir() is None
    save_stage(key, {"x": 1})  # no folder: nothing stored, nothing found
    assert load_stage(key) is None
    with stage_checkpoints(tmp_path):
        assert load_stage(key) is None
        save_stage(key, {"x": torch.ones(2)})
        assert torch.equal(load_stage(key)["x"], torch.ones(2))
        assert not [p for p in tmp_path.iterdir() if p.suffix != ".pt"]  # atomic: no temporary left
        (tmp_path / f"{key}.pt").write_bytes(b"not a checkpoint")  # damaged: warned about, then trained anew
        with pytest.warns(UserWarning, match="unreadable stage checkpoint"):
            assert load_stage(key) is None
    assert checkpoint_dir() is None
    with stage_checkpoints(tmp_path, {"blas": "mkl-generic"}):  # the harness's rounding facts enter the key
        assert stage_key({"a": 1}) != key
    assert tensor_digest(torch.zeros(2)) != tensor_digest(torch.zeros(3)) != tensor_digest(None)


def _fit(scene, over: dict) -> tuple:
    art = MonoInstance().fit(scene, method_config("monoinstance", "tiny", {**TINY, **over}), seed=0)
    return art, [(s.iterations, np.asarray(s.mesh.vertices), np.asarray(s.mesh.faces)) for s in art.snapshots]


@pytest.mark.slow
def test_a_row_resumed_from_the_shared_stage_ends_where_training_every_step_ends(tiny_scene, tmp_path: Path):
    reference, ref_meshes = _fit(tiny_scene, {})  # Full, no cache folder: every step trained here
    assert "train_shared" not in reference.timings
    with stage_checkpoints(tmp_path):
        base, _ = _fit(tiny_scene, BASE)  # the Base row trains stage 1 and stores it
        assert "train_shared" not in base.timings and len(list(tmp_path.glob("*.pt"))) == 1
        full, meshes = _fit(tiny_scene, {})  # the Full row loads it
        assert full.timings["train_shared"] > 0 and full.timings["train"] >= full.timings["train_shared"]
        assert full.snapshots[0].seconds >= full.timings["train_shared"]  # the time axis counts the loaded stage's cost
        other, _ = _fit(tiny_scene, {"depth_weight": 0.3})  # a MonoSDF key differs: another stage 1, trained here
        assert "train_shared" not in other.timings and len(list(tmp_path.glob("*.pt"))) == 2
        early, _ = _fit(tiny_scene, {"fractions": [0.125, 1.0]})  # a snapshot inside stage 1: nothing to load it from
        assert "train_shared" not in early.timings
    assert [m[0] for m in meshes] == [m[0] for m in ref_meshes] == [4, 8, 16]
    for (_, v, f), (_, rv, rf) in zip(meshes, ref_meshes):
        np.testing.assert_array_equal(v, rv)  # the same bytes, not merely close
        np.testing.assert_array_equal(f, rf)
    np.testing.assert_array_equal(full.uncertainty, reference.uncertainty)
    assert full.extra["beta"] == reference.extra["beta"]


@pytest.mark.slow
def test_a_stage_trained_while_another_process_builds_the_kernel_books_its_training_only(tiny_scene, tmp_path: Path,
                                                                                        monkeypatch):
    """The first use of the C++ kernel waits for a build another process holds (its ``bench-build.lock``): the
    stored stage-1 seconds and the job's setup + train seconds leave that wait out (a later row loading the stage
    would book it forever)."""
    import fcntl
    import threading
    import time

    from methods.cpp_build import CppExtension
    from methods.monosdf import grid

    if not grid.fast_available():
        pytest.skip("no C++ compiler")
    k = grid._KERNEL
    fresh = CppExtension(k.name, grid.__file__, tuple(p.name for p in k.sources), k.cflags, k.ldflags)
    monkeypatch.setattr(grid, "_KERNEL", fresh)  # not loaded yet in this process: its first use takes the lock
    hold_s = 6.0
    with open(fresh.build_dir() / "bench-build.lock", "a+") as held:
        fcntl.flock(held, fcntl.LOCK_EX)  # another process's build, still running
        release = threading.Timer(hold_s, lambda: fcntl.flock(held, fcntl.LOCK_UN))
        release.start()
        try:
            with stage_checkpoints(tmp_path):
                t = time.perf_counter()
                art, _ = _fit(tiny_scene, BASE)
                wall = time.perf_counter() - t
        finally:
            release.join()
    stored = torch.load(next(tmp_path.glob("*.pt")), weights_only=False)["train_seconds"]
    assert fresh.load() is not None and wall > hold_s
    assert 0 < stored < wall - 0.8 * hold_s
    assert art.timings["setup"] + art.timings["train"] < wall - 0.8 * hold_s
