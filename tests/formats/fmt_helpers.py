"""Shared helpers for the format tests."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from bench.data.formats import write_scene
from bench.data.scene import Scene

FORMATS = ("scannet", "replica", "dtu", "llff")

# files / folders that are ours, not the real format's
EXTRA_GLOBS = (
    "meta.json", "segments.json", "instances.json", "gt_mesh.ply",
    "*_gt_depth.npy", "*_gt_normal.npy", "*_gt_instance.png", "*_seg.png",
    "gt_depth", "gt_normal", "gt_instance", "seg", "mono_depth", "mono_normal",
)


def write(scene: Scene, root: Path, fmt: str, **kw) -> Path:
    root.mkdir(parents=True)
    write_scene(scene, root, fmt, **kw)
    return root


def strip_extras(root: Path, keep_priors: bool = False) -> None:
    for pattern in EXTRA_GLOBS:
        if keep_priors and pattern in ("mono_depth", "mono_normal"):
            continue
        for p in root.glob(pattern):
            shutil.rmtree(p) if p.is_dir() else p.unlink()


def quantised(images: np.ndarray) -> np.ndarray:
    return (np.round(np.clip(images, 0, 1) * 255).astype(np.uint8)).astype(np.float32) / np.float32(255)
