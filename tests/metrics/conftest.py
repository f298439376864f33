"""Shared fixtures for the metric tests (cameras around a small scene, real meshes when present)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ASSETS = Path(__file__).resolve().parents[3] / "shared" / "assets" / "meshes"


def look_at(eye, target, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """cam_to_world (4, 4), OpenCV axes (x right, y down, z forward)."""
    eye, target, up = (np.asarray(a, dtype=np.float64) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, eye
    return c2w


@pytest.fixture
def ring_cameras():
    """8 cameras on a ring of radius 2.5 m at height 0.8 m looking at the origin; 48 x 64 images."""
    H, W = 48, 64
    K = np.array([[50.0, 0.0, 31.5], [0.0, 50.0, 23.5], [0.0, 0.0, 1.0]])
    c2w = np.stack([look_at((2.5 * np.cos(a), 2.5 * np.sin(a), 0.8), (0, 0, 0)) for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)])
    return K, c2w, H, W


@pytest.fixture
def real_mesh():
    """Loader of a third-party mesh from ../shared/assets/meshes (skips the test when absent)."""

    def load(name: str):
        import trimesh

        p = ASSETS / name
        if not p.exists():
            pytest.skip(f"real mesh asset {p} not available")
        return trimesh.load(p, force="mesh", process=False)

    return load
