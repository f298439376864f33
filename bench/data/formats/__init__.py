"""On-disk dataset formats: writers and loaders. Formats stop here; methods only ever see a Scene.

Public API::

    write_scene(scene, out_dir, fmt, gt_mesh=None, **fmt_options) -> None
    load_scene(path, fmt=None, **options) -> Scene
    detect_format(path) -> str

Formats (``bench.data.scene.DATASET_FORMATS``) and the files each loader REQUIRES (everything else optional):

* ``scannet`` / ``replica`` (:mod:`bench.data.formats.monosdf`, MonoSDF's preprocessed layout):
  ``cameras.npz`` (``world_mat_i``, ``scale_mat_i``) and ``*_rgb.png``. Optional real files:
  ``*_depth.npy``, ``*_normal.npy`` (mono priors), Replica ``*_mask.npy``.
* ``dtu`` (:mod:`bench.data.formats.dtu`, IDR / NeuS layout): ``image/*.png`` and ``cameras.npz`` (or
  ``cameras_sphere.npz``). Optional real files: ``mask/*.png``. Option ``train_views``.
* ``llff`` (:mod:`bench.data.formats.llff`): ``poses_bounds.npy`` and ``images/`` (or ``images_{factor}/``
  when loading with option ``factor``). Writer options ``factors``, ``bounds``, ``image_name``.

Our extras (GT depth / normals / instance ids, per-view segments, background flags, instance table,
GT mesh, meta.json) are described in :mod:`bench.data.formats.extras`; a loader returns None / empty for the
fields whose files are absent, so real preprocessed data loads without them. See ``docs/formats.md``.

Every problem with the input raises one :class:`bench.data.errors.BenchInputError` naming the file and
the problem; every loader ends with ``Scene.validate()``. Writing is deterministic: the same Scene
written twice gives byte-identical files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from bench.data.errors import BenchInputError
from bench.data.formats import dtu, llff, monosdf
from bench.data.formats.extras import META_FILE, read_json
from bench.data.scene import DATASET_FORMATS, Scene

__all__ = ["write_scene", "load_scene", "detect_format", "DATASET_FORMATS"]


def _check_format(fmt: str, where: str | Path) -> None:
    if fmt not in DATASET_FORMATS:
        raise BenchInputError(where, f"unknown format {fmt!r} (known: {', '.join(DATASET_FORMATS)})")


def write_scene(scene: Scene, out_dir: Path, fmt: str, gt_mesh: Any = None, **fmt_options: Any) -> None:
    """Write ``scene`` into the EXISTING, empty folder ``out_dir`` in format ``fmt``.

    Make it atomic with ``bench.data.atomic.atomic_directory``. ``gt_mesh`` (a ``trimesh.Trimesh`` in world
    metres) is written as ``gt_mesh.ply``; without it, ``scene.gt_mesh_path`` is copied if it exists.

    Args:
        scene: the scene (``scene.validate()`` is called first).
        out_dir: existing empty folder.
        fmt: one of ``DATASET_FORMATS``.
        fmt_options: llff only: ``factors`` (tuple of int), ``bounds`` ((near, far) metres, used
            without GT depth), ``image_name`` (default ``"IMG_{i:04d}.png"``).

    Raises:
        BenchInputError: unknown format or option, folder missing / not empty, scene not representable.
    """
    out_dir = Path(out_dir)
    _check_format(fmt, out_dir)
    if not out_dir.is_dir():
        raise BenchInputError(out_dir, "output folder does not exist")
    if any(out_dir.iterdir()):
        raise BenchInputError(out_dir, "output folder is not empty")
    scene.validate()
    allowed = {"llff": {"factors", "bounds", "image_name"}}.get(fmt, set())
    unknown = set(fmt_options) - allowed
    if unknown:
        raise BenchInputError(out_dir, f"unknown option(s) {sorted(unknown)} for format {fmt!r}")
    if fmt in ("scannet", "replica"):
        monosdf.write(scene, out_dir, fmt, gt_mesh)
    elif fmt == "dtu":
        dtu.write(scene, out_dir, fmt, gt_mesh)
    else:
        llff.write(scene, out_dir, fmt, gt_mesh, **fmt_options)


def detect_format(path: Path) -> str:
    """Guess the format of a dataset folder.

    ``meta.json``'s ``format`` if present; else ``poses_bounds.npy`` -> llff; ``image/`` + ``cameras.npz``
    (or ``cameras_sphere.npz``) -> dtu; ``cameras.npz`` + ``*_rgb.png`` -> replica if ``*_mask.npy``
    files exist, else scannet. BenchInputError if none matches.
    """
    path = Path(path)
    if not path.is_dir():
        raise BenchInputError(path, "dataset folder does not exist")
    meta_path = path / META_FILE
    looks_like = format_from_files(path)
    if meta_path.is_file():
        meta = read_json(meta_path)
        fmt = meta.get("format") if isinstance(meta, dict) else None
        if fmt is not None:
            _check_format(fmt, meta_path)
            if looks_like is not None and _family(looks_like) != _family(fmt) and format_from_files(path, only=fmt) is None:
                raise BenchInputError(meta_path, f"says format {fmt!r}, but the folder's files are those of {looks_like!r} "
                                      f"({FORMAT_FILES[looks_like]}) and not those of {fmt!r} ({FORMAT_FILES[fmt]}); "
                                      f"correct its 'format' or remove meta.json")
            return str(fmt)
    if looks_like is not None:
        return looks_like
    raise BenchInputError(
        path, "unknown dataset format (no meta.json, poses_bounds.npy, image/ + cameras.npz or cameras.npz + *_rgb.png)"
    )


FORMAT_FILES = {"llff": "poses_bounds.npy", "dtu": "image/ + cameras.npz", "scannet": "cameras.npz + *_rgb.png",
                "replica": "cameras.npz + *_rgb.png + *_mask.npy"}
"""The files that tell each format apart (:func:`format_from_files`), as the messages name them."""


def _family(fmt: str) -> str:
    """Formats with the same files (replica is scannet's layout plus masks) count as one."""
    return "scannet" if fmt == "replica" else fmt


def format_from_files(path: Path, only: str | None = None) -> str | None:
    """The format a folder's files look like (:data:`FORMAT_FILES`), or None; ``only``: test that format alone
    (replica and scannet share their files: either matches the other)."""
    checks = {
        "llff": lambda: (path / llff.POSES_FILE).is_file(),
        "dtu": lambda: (path / dtu.IMAGE_DIR).is_dir() and ((path / monosdf.CAMERAS_FILE).is_file() or (path / "cameras_sphere.npz").is_file()),
        "scannet": lambda: (path / monosdf.CAMERAS_FILE).is_file() and any(path.glob("*_rgb.png")),
    }
    for fmt, check in checks.items():
        if (only is None or _family(only) == fmt) and check():
            if fmt == "scannet":
                return "replica" if any(path.glob("*_mask.npy")) else "scannet"
            return fmt
    return None


def load_scene(path: Path, fmt: str | None = None, **options: Any) -> Scene:
    """Load a dataset folder as a validated :class:`Scene` (poses in world metres, OpenCV axes).

    Args:
        path: dataset folder.
        fmt: format, autodetected with :func:`detect_format` when None.
        options: dtu: ``train_views`` (sequence of int); llff: ``factor`` (int, default 1).

    Raises:
        BenchInputError naming the file and the problem.
    """
    path = Path(path)
    if fmt is None:
        fmt = detect_format(path)
    _check_format(fmt, path)
    if not path.is_dir():
        raise BenchInputError(path, "dataset folder does not exist")
    allowed = {"dtu": {"train_views"}, "llff": {"factor"}}.get(fmt, set())
    unknown = set(options) - allowed
    if unknown:
        raise BenchInputError(path, f"unknown option(s) {sorted(unknown)} for format {fmt!r}")
    if fmt in ("scannet", "replica"):
        return monosdf.load(path, fmt)
    if fmt == "dtu":
        return dtu.load(path, **options)
    return llff.load(path, **options)
