"""A small seeded synthetic Scene for the format tests."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from bench.data.scene import InstanceInfo, Scene
from metrics.camera import look_at

N, H, W = 5, 24, 32


def unit_normals(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    n = rng.normal(size=shape + (3,))
    n[..., 2] = -np.abs(n[..., 2]) - 0.1  # facing the camera
    return (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)


def make_scene(seed: int = 0) -> Scene:
    rng = np.random.default_rng(seed)
    poses = []
    for i in range(N):
        a = 2 * np.pi * i / N
        eye = np.array([2.0 * np.cos(a), 2.0 * np.sin(a), 0.5 + 0.2 * i])
        poses.append(look_at(eye, np.array([0.05, -0.02, 0.1])))
    K = np.array([[30.0, 0.0, (W - 1) / 2], [0.0, 30.0, (H - 1) / 2], [0.0, 0.0, 1.0]])
    ang = 0.3
    Q = np.array([[np.cos(ang), -np.sin(ang), 0], [np.sin(ang), np.cos(ang), 0], [0, 0, 1]])
    scale_mat = np.eye(4)
    scale_mat[:3, :3] = 2.5 * Q
    scale_mat[:3, 3] = [0.1, -0.2, 0.3]

    mono_depth = rng.uniform(0.5, 3.0, (N, H, W)).astype(np.float32)
    mono_depth[:, :2, :3] = 0.0
    gt_depth = rng.uniform(1.0, 3.0, (N, H, W)).astype(np.float32)
    gt_depth[:, -3:, :] = 0.0
    gt_normal = unit_normals(rng, (N, H, W))
    gt_normal[gt_depth == 0] = 0.0
    gt_instance = rng.integers(0, 5, (N, H, W)).astype(np.int32)
    gt_instance[gt_depth == 0] = 0
    seg = rng.integers(0, 4, (N, H, W)).astype(np.int32)
    seg[0, 0, 0] = 1000  # > 8 bit
    seg_bg = [{1: True, 2: False, 3: False, 1000: False} for _ in range(N)]
    instances = {
        1: InstanceInfo(1, "wall_north", "wall", True, False),
        2: InstanceInfo(2, "floor", "floor", True, False),
        3: InstanceInfo(3, "chair_0", "chair", False, True),
        4: InstanceInfo(4, "table_0", "table", False, False),
    }
    return Scene(
        name="tiny_test_scene",
        kind="room",
        source_format="scannet",
        images=rng.random((N, H, W, 3)).astype(np.float32),
        intrinsics=np.stack([K] * N),
        cam_to_world=np.stack(poses),
        scale_mat=scale_mat,
        mono_depth=mono_depth,
        mono_normal=unit_normals(rng, (N, H, W)),
        seg_masks=seg,
        seg_background=seg_bg,
        gt_depth=gt_depth,
        gt_normal=gt_normal,
        gt_instance=gt_instance,
        instances=instances,
        splits={"train": np.array([0, 2, 4]), "eval_only": np.array([1, 3])},
        metadata={"recipe": "unit-test", "seed": seed, "effects": [{"name": "depth_noise", "sigma": 0.01}]},
    )


@pytest.fixture()
def scene() -> Scene:
    return make_scene()


@pytest.fixture()
def gt_mesh() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(1.0, 0.8, 0.6))
