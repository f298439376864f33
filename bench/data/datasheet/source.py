"""What ``bench scenes card`` measures: a recipe synthesised in memory, or a dataset folder with its GT."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bench.data.errors import BenchInputError
from bench.data.scene import Scene


def expected_view_file(root: Path, fmt: str, kind: str) -> Path:
    """Where view 0's per-view map ``kind`` (``gt_depth``, ``gt_instance``, ...) lives in a dataset folder
    of format ``fmt`` (:mod:`bench.data.formats.extras` layouts)."""
    from bench.data.formats.extras import Layout

    if fmt in ("scannet", "replica"):
        rgb = sorted(root.glob("*_rgb.png"))
        prefix = rgb[0].name[: -len("_rgb.png")] if rgb else f"{0:06d}"
        return Layout(root, (prefix,), flat=True).path(kind, 0)
    return Layout(root, (f"{0:06d}",), flat=False).path(kind, 0)


def load_folder_with_gt(root: Path) -> tuple[Scene, Any | None]:
    """Load a dataset folder (format detected) and its GT mesh if present.

    Raises:
        BenchInputError: naming the first missing file the datasheet needs (GT depth, GT instance ids,
        the instance table); a missing GT mesh is not an error (the capture statistics then use
        back-projected GT depth).
    """
    from bench.data.formats import detect_format, load_scene
    from bench.data.formats.extras import INSTANCES_FILE

    root = Path(root)
    fmt = detect_format(root)
    scene = load_scene(root, fmt)
    for kind in ("gt_depth", "gt_instance"):
        if getattr(scene, kind) is None:
            raise BenchInputError(expected_view_file(root, fmt, kind), f"file is missing: the datasheet needs the {kind} of every view")
    if not scene.instances:
        raise BenchInputError(root / INSTANCES_FILE, "file is missing: the datasheet needs the GT instance table")
    mesh = scene.load_gt_mesh() if scene.gt_mesh_path is not None else None
    return scene, mesh


def card_sheet(target: str, scale: str, seed: int | None, scenes_dir: Path) -> dict[str, Any]:
    """The datasheet ``bench scenes card TARGET`` shows: an existing folder is loaded and measured;
    anything else is a recipe (a path, or a name in ``scenes_dir``) synthesised in memory at ``scale`` /
    ``seed``, whose datasheet the synthesis computed."""
    from bench.data.synth.make import make_scene
    from bench.data.synth.recipe import load_recipe

    from .sheet import compute_datasheet

    path = Path(target)
    if path.is_dir():
        if seed is not None:
            raise BenchInputError("--seed", "applies to a recipe, not to a dataset folder")
        return compute_datasheet(*load_folder_with_gt(path))
    if not path.exists() and (scenes_dir / f"{target}.yaml").exists():
        path = scenes_dir / f"{target}.yaml"
    scene, _ = make_scene(load_recipe(path), scale=scale, seed=seed)
    return scene.metadata["datasheet"]
