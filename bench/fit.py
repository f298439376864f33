"""``bench fit METHOD PATH``: one method on any dataset folder in the four formats (a user's own data).

The folder is loaded with :func:`bench.data.formats.load_scene` (format detected from its files; LLFF at
``--factor``), the method trained with its config at ``--scale`` plus ``--set`` overrides, and every
snapshot evaluated with the format's protocol where the folder holds the ground truth it needs
(``gt_mesh.ply`` for the geometry protocols; the held-out views for LLFF). Without it the run still
keeps the mesh / maps and says which file would enable the metrics.

Outputs in ``--out``: ``fit.json`` (the result row: config, timings, the curve of metrics or the reason
there are none; ``smoke_test`` says when the scale is a smoke test, :mod:`bench.scales`), ``fit.md`` (a short summary) and the artifacts (:mod:`bench.artifacts`: ``mesh.ply``,
uncertainty maps, renders).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

from bench.data.atomic import atomic_write_json, atomic_write_text
from bench.data.errors import BenchInputError


def fit_folder(method: str, path: Path, scale: str, overrides: dict[str, Any], out: Path, seed: int = 0,
               factor: int | None = None, log: Callable[[str], None] = print) -> dict[str, Any]:
    """Train ``method`` on the dataset folder ``path``; evaluate where GT is present; write ``out``.

    Returns:
        The result row (also written to ``out/fit.json``).
    """
    from bench.artifacts import write_job_artifacts
    from bench.data.formats import detect_format, load_scene
    from bench.evaluate import evaluate_snapshot
    from bench.scales import smoke_note
    from methods.cpp_build import OwnClock
    from methods.registry import get_method, method_config

    path = Path(path)
    cfg = method_config(method, scale, overrides)  # an unknown method or key: said before the data is read
    if not path.is_dir():
        raise BenchInputError(path, "dataset folder does not exist")
    fmt = detect_format(path)
    scene = load_scene(path, fmt, **({"factor": int(factor)} if fmt == "llff" and factor else {}))
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    log(f"[fit] {method} on {path} ({fmt}, {scene.num_views} views {scene.width}x{scene.height}), scale {scale}, seed {seed}")
    smoke = smoke_note(scale)
    if smoke:
        log(f"[fit] {smoke}")
    clock = OwnClock()  # the fit's own time: a first-use C++ kernel build is left out
    last = [0.0]

    def progress(frac: float, msg: str) -> None:
        if time.perf_counter() - last[0] > 10:  # a plain line every 10 s
            last[0] = time.perf_counter()
            log(f"[fit] {frac:4.0%} {msg}")

    artifacts = get_method(method).fit(scene, cfg, seed, progress)
    fit_s = clock.seconds()
    curve, no_metrics = [], None
    has_gt = fmt == "llff" or scene.gt_mesh_path is not None
    if not has_gt:
        no_metrics = f"{path / 'gt_mesh.ply'} is missing: no metrics (the {fmt} protocol compares against the GT mesh)"
    for snap in artifacts.snapshots:
        point: dict[str, Any] = {"fraction": snap.fraction, "iterations": snap.iterations, "seconds": snap.seconds}
        if has_gt:
            try:
                point["metrics"] = evaluate_snapshot(snap, scene, fmt, scale, seed=seed)
            except (ValueError, BenchInputError) as exc:
                point["error"] = f"{type(exc).__name__}: {exc}"
        curve.append(point)
    files = write_job_artifacts(artifacts, scene, out / "artifacts")
    row = {"method": method, "dataset": str(path), "format": fmt, "scale": scale, "seed": seed, "config": cfg,
           "fit_seconds": fit_s, "iterations": artifacts.iterations, "timings": artifacts.timings, "curve": curve,
           "metrics": (curve[-1].get("metrics") or {}) if curve else {}, "no_metrics": no_metrics, "smoke_test": smoke or None,
           "artifacts": {"dir": "artifacts", "files": files}}
    atomic_write_json(out / "fit.json", row)
    lines = [f"# {method} on `{path}`", "", f"{fmt}, {scene.num_views} views {scene.width}x{scene.height}; scale {scale}, "
             f"seed {seed}; {artifacts.iterations} iterations in {fit_s:.0f} s", ""]
    if smoke:
        lines += [f"**Smoke test.** {smoke}", ""]
    if no_metrics:
        lines.append(f"No metrics: {no_metrics}.")
    else:
        keys = sorted({k for p in curve for k in (p.get("metrics") or {})})
        lines += ["| fraction | iterations | seconds | " + " | ".join(keys) + " |", "|---" * (3 + len(keys)) + "|"]
        for p in curve:
            m = p.get("metrics") or {}
            lines.append(f"| {p['fraction']:.2f} | {p['iterations']} | {p['seconds']:.0f} | "
                         + " | ".join(f"{m[k]:.4f}" if k in m else "-" for k in keys) + " |")
    lines += ["", f"Artifacts: {', '.join(files) or 'none'} (in `artifacts/`)."]
    atomic_write_text(out / "fit.md", "\n".join(lines) + "\n")
    log("\n".join(lines))
    return row
