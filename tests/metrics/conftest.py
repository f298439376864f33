"""Shared fixtures for the metric tests (cameras around a small scene, real meshes when present)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from metrics.camera import look_at

ASSETS = Path(__file__).resolve().parents[3] / "shared" / "assets" / "meshes"


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
