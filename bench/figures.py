"""Report figures: the accuracy-vs-time plot from the result rows, and figures drawn from the per-job
artifacts (:mod:`bench.artifacts`).

:func:`plot_accuracy_vs_time`: a table's main metric against wall seconds, one curve per row (the mean
along the schedule, :func:`bench.aggregate.curve_table`, and the mean final point), one panel per group.

:func:`reconstruction_figure`: for every geometry group of a table, one scene (its first) and one seed
(the smallest), every measured row's final mesh ray-cast from 2 fixed training cameras, each pixel
coloured by the distance of the surface point it sees to the GT mesh (0 .. ``VMAX_M``; grey = the mesh
has no surface there), beside the GT mesh seen from the same cameras (shaded by its normals). What a
table's F-score summarises, where it goes wrong.

:func:`uncertainty_figure`: for every row that kept uncertainty maps (MonoInstance), 3 views of its first
scene / seed: the image, the estimated uncertainty and the true error of the depth prior
(|prior aligned to GT by per-view scale + shift - GT depth|, the paper's Figs. 2 / 3 / 6 argument: the
uncertainty should be high where the prior is wrong).

:func:`renders_figure`: for every view-synthesis row (LLFF), its renders of 2 test views beside the GT
images, and its rendered depth beside the GT depth (same colour scale, metres).
"""

from __future__ import annotations

import io
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from bench.aggregate import curve_table
from bench.scales import is_smoke
from bench.table_report import TableReport
from metrics.camera import backproject

VMAX_M = 0.10  # colour scale of the distance to GT (m): the F-score threshold is 5 cm
GEOMETRY_PROTOCOLS = ("scannet", "replica", "dtu")


def _raycasting_scene(mesh: Any) -> Any:
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)), o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    return scene


def distance_image(mesh: Any, gt_scene: Any, K: np.ndarray, c2w: np.ndarray, h: int, w: int) -> np.ndarray:
    """(H, W) distance (m) from the surface of ``mesh`` seen at each pixel to the GT mesh (``gt_scene``:
    its :func:`_raycasting_scene`, built once per figure panel); NaN where the ray hits nothing."""
    import open3d as o3d

    from metrics.render import render_depth_maps

    depth = render_depth_maps(mesh, K[None], c2w[None], h, w)[0]
    pts = backproject(depth, K, c2w)
    d = gt_scene.compute_distance(o3d.core.Tensor(pts.reshape(-1, 3).astype(np.float32))).numpy().reshape(h, w)
    return np.where(depth > 0, d, np.nan)


def shaded_image(mesh: Any, K: np.ndarray, c2w: np.ndarray, h: int, w: int) -> np.ndarray:
    """(H, W) grey shading |n . view ray| of ``mesh`` (0 where nothing is hit)."""
    import open3d as o3d

    scene = _raycasting_scene(mesh)
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    dirs = np.stack([u, v, np.ones_like(u)], -1) @ np.linalg.inv(K).T @ c2w[:3, :3].T
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    rays = np.concatenate([np.broadcast_to(c2w[:3, 3], dirs.shape), dirs], -1).reshape(-1, 6).astype(np.float32)
    ans = scene.cast_rays(o3d.core.Tensor(rays))
    n = ans["primitive_normals"].numpy().reshape(h, w, 3)
    hit = np.isfinite(ans["t_hit"].numpy().reshape(h, w))
    return np.where(hit, np.abs((n * dirs).sum(-1)), 0.0)


def reconstruction_figure(report: Any, out_dir: Path, cache_dir: Path | None = None) -> bytes | None:
    """PNG (see the module docstring) for ``report`` (a :class:`bench.table_report.TableReport`) from the meshes
    under ``out_dir/artifacts``; None when no row of a geometry group has a kept mesh."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import trimesh

    from bench.data.datasets import DEFAULT_CACHE, load_dataset

    panels = [(g.label, scene_name, rows) for g, scene_name, _seed, rows in _first_jobs(report, out_dir, "mesh.ply", GEOMETRY_PROTOCOLS)]
    if not panels:
        return None
    n_rows = sum(1 + len(rows) for _, _, rows in panels)
    fig, ax = plt.subplots(n_rows, 2, figsize=(7.6, 2.4 * n_rows), squeeze=False)
    k = 0
    im = None
    for label, scene_name, rows in panels:
        scene = load_dataset(scene_name, report.scale, cache_dir or DEFAULT_CACHE)
        gt = scene.load_gt_mesh()
        gt_scene = _raycasting_scene(gt)
        views = scene.view_indices("train")
        cams = [int(views[0]), int(views[len(views) // 2])]
        for j, v in enumerate(cams):
            ax[k, j].imshow(shaded_image(gt, scene.intrinsics[v], scene.cam_to_world[v], scene.height, scene.width), cmap="gray", vmin=0, vmax=1)
            ax[k, j].set_title(f"GT, view {v}", fontsize=7)
        ax[k, 0].set_ylabel(textwrap.fill(f"{label} / {scene_name}", 24), fontsize=7)
        k += 1
        for row_label, path in rows:
            mesh = trimesh.load(path, force="mesh", process=False)
            for j, v in enumerate(cams):
                d = distance_image(mesh, gt_scene, scene.intrinsics[v], scene.cam_to_world[v], scene.height, scene.width)
                ax[k, j].set_facecolor("0.6")
                im = ax[k, j].imshow(np.clip(d, 0, VMAX_M), cmap="viridis", vmin=0, vmax=VMAX_M)
                ok = np.isfinite(d)
                frac = float((d[ok] < 0.05).mean()) if ok.any() else 0.0
                ax[k, j].set_title(f"view {v}: {100 * frac:.0f} % of pixels < 5 cm", fontsize=7)
            ax[k, 0].set_ylabel(textwrap.fill(row_label, 24), fontsize=7)
            k += 1
    for a in ax.ravel():
        a.set_xticks([])
        a.set_yticks([])
    if im is not None:
        fig.colorbar(im, ax=ax.ravel().tolist(), shrink=0.3, label="distance to GT (m); grey: no surface")
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return buf.getvalue()


def _first_jobs(report: Any, out_dir: Path, want: str, protocols: tuple[str, ...] | None = None) -> list[tuple[Any, str, int, list[tuple[str, Path]]]]:
    """Per group (optionally of these protocols): (group, first scene, smallest seed, [(row label,
    artifact file ``want``)]) for the rows whose job kept that file."""
    jobs = report.jobs
    out: list[tuple[Any, str, int, list[tuple[str, Path]]]] = []
    if jobs is None or not len(jobs):
        return out
    for g in report.spec.groups:
        if protocols and g.protocol not in protocols:
            continue
        mine = jobs[(jobs["group"].astype(object) == g.id) & (jobs["status"] == "ok")]
        if not len(mine):
            continue
        scene_name = sorted(mine["scene"].unique())[0]
        seed = int(mine[mine["scene"] == scene_name]["seed"].min())
        rows = []
        for r in report.spec.rows:
            hit = mine[(mine["row"] == r.label) & (mine["scene"] == scene_name) & (mine["seed"] == seed)]
            if len(hit):
                path = Path(out_dir) / "artifacts" / str(hit.iloc[0]["job_id"]) / want
                if path.is_file():
                    rows.append((r.label, path))
        if rows:
            out.append((g, scene_name, seed, rows))
    return out


def prior_error_maps(scene: Any, views: np.ndarray) -> np.ndarray:
    """(V, H, W) |mono depth aligned to GT (per-view LSQ scale + shift) - GT depth| (m); NaN where either
    is invalid or the view cannot be aligned."""
    from metrics.depth import align_depth

    out = np.full((len(views), scene.height, scene.width), np.nan, dtype=np.float32)
    for i, v in enumerate(views):
        prior, gt = scene.mono_depth[v].astype(np.float64), scene.gt_depth[v].astype(np.float64)
        valid = (prior > 0) & (gt > 0)
        try:
            s, t = align_depth(prior, gt, valid)
        except ValueError:
            continue
        out[i] = np.where(valid, np.abs(s * prior + t - gt), np.nan)
    return out


def grid_png(cells: list[list[tuple[np.ndarray, str, dict[str, Any]]]], ylabels: list[str] | None = None) -> bytes:
    """PNG of a grid of images: ``cells[row][col] = (image, title, imshow keywords)``; ``ylabels`` name the
    rows. Shared by the report figures and the per-job previews (:mod:`bench.artifacts`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_r, n_c = len(cells), max(len(r) for r in cells)
    fig, ax = plt.subplots(n_r, n_c, figsize=(2.5 * n_c, 2.1 * n_r), squeeze=False)
    for i, row in enumerate(cells):
        for j in range(n_c):
            ax[i, j].set_xticks([])
            ax[i, j].set_yticks([])
            if j < len(row):
                img, title, kw = row[j]
                ax[i, j].imshow(img, **kw)
                ax[i, j].set_title(title, fontsize=7)
        if ylabels:
            ax[i, 0].set_ylabel(textwrap.fill(ylabels[i], 22), fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return buf.getvalue()


def uncertainty_figure(report: Any, out_dir: Path, cache_dir: Path | None = None) -> bytes | None:
    """PNG: image / estimated uncertainty / true prior error for 3 views of every row with kept maps."""
    from bench.data.datasets import DEFAULT_CACHE, load_dataset

    cells, labels = [], []
    for g, scene_name, _seed, rows in _first_jobs(report, out_dir, "uncertainty.npy"):
        scene = load_dataset(scene_name, report.scale, cache_dir or DEFAULT_CACHE, effects=dict(g.effects) or None)
        if scene.mono_depth is None or scene.gt_depth is None:
            continue
        for label, path in rows:
            unc = np.load(path).astype(np.float32)
            views = scene.view_indices("train") if len(unc) != scene.num_views else np.arange(scene.num_views)
            pick = np.linspace(0, len(unc) - 1, min(3, len(unc))).round().astype(int)
            err = prior_error_maps(scene, views[pick])
            for k, i in enumerate(pick):
                v = int(views[i])
                cells.append([(scene.images[v], f"{scene_name} view {v}", {}),
                              (unc[i], "estimated uncertainty", {"cmap": "inferno", "vmin": 0, "vmax": 1}),
                              (np.clip(err[k], 0, 0.3), "true prior error 0-30 cm", {"cmap": "inferno", "vmin": 0, "vmax": 0.3})])
                labels.append(f"{g.label}: {label}")
    return grid_png(cells, labels) if cells else None


def renders_figure(report: Any, out_dir: Path, cache_dir: Path | None = None) -> bytes | None:
    """PNG: 2 test views of every view-synthesis row: render, GT image, rendered depth, GT depth."""
    from bench.data.datasets import DEFAULT_CACHE, load_dataset

    cells, labels = [], []
    for g, scene_name, _seed, rows in _first_jobs(report, out_dir, "renders.npy", ("llff",)):
        scene = load_dataset(scene_name, report.scale, cache_dir or DEFAULT_CACHE)
        test = scene.view_indices("test")
        for label, path in rows:
            renders = np.load(path).astype(np.float32)
            depths = np.load(path.with_name("depths.npy")).astype(np.float32) if path.with_name("depths.npy").is_file() else None
            pick = np.linspace(0, len(renders) - 1, min(2, len(renders))).round().astype(int)
            row: list[tuple[np.ndarray, str, dict[str, Any]]] = []
            for i in pick:
                v = int(test[i])
                row += [(np.clip(renders[i], 0, 1), f"render, test view {v}", {}), (scene.images[v], "GT", {})]
                if depths is not None:
                    gt_d = scene.gt_depth[v] if scene.gt_depth is not None else None
                    hi = float(np.percentile(gt_d[gt_d > 0], 99)) if gt_d is not None and (gt_d > 0).any() else float(depths[i].max() or 1.0)
                    kw = {"cmap": "viridis", "vmin": 0.0, "vmax": hi}
                    row.append((np.where(depths[i] > 0, depths[i], np.nan), "rendered depth", kw))
                    if gt_d is not None:
                        row.append((np.where(gt_d > 0, gt_d, np.nan), "GT depth", kw))
            cells.append(row)
            labels.append(f"{g.label}: {label}")
    return grid_png(cells, labels) if cells else None


def _curves(report: TableReport, curves: pd.DataFrame, gid: str, key: str) -> dict[str, tuple[list[float], list[float], tuple[float, float] | None]]:
    """Per row: mean (seconds, metric) per curve fraction (from ``curves``, :func:`curve_table`), and the
    mean final (total s, metric) point."""
    out = {}
    curves = curves[(curves["group"] == gid) & (curves["metric"] == key)].sort_values("fraction")
    ok = report.jobs[(report.jobs["status"] == "ok") & (report.jobs["gid"] == gid)]
    for label, sub in ok.groupby("row", sort=False):
        c = curves[curves["row"] == str(label)]
        total = pd.to_numeric(sub["timings"].map(lambda t: t.get("total")), errors="coerce")
        final = pd.to_numeric(sub["metrics"].map(lambda m: m.get(key)), errors="coerce")
        both = pd.DataFrame({"t": total, "v": final}).dropna()
        end = (float(both["t"].mean()), float(both["v"].mean())) if len(both) else None
        out[str(label)] = (c["seconds"].tolist(), c["mean"].tolist(), end)
    order = [r.label for r in report.spec.rows]
    return dict(sorted(out.items(), key=lambda kv: order.index(kv[0]) if kv[0] in order else len(order)))


def plot_accuracy_vs_time(report: TableReport, curves: pd.DataFrame | None = None) -> bytes:
    """PNG bytes: the main metric against wall seconds, one curve per row, one panel per group
    (``curves``: :func:`curve_table` of ``report`` when the caller has it already)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    _, main = report.spec.main_metric()
    groups = [g for g in report.spec.groups if g.column(main.key) is not None and not g.column(main.key).paper_only]  # type: ignore[union-attr]
    curves = curve_table(report) if curves is None else curves
    colours = {r.label: f"C{k % 10}" for k, r in enumerate(report.spec.rows)}  # one colour per row in every panel
    fig = Figure(figsize=(5.0 * len(groups), 3.8))
    FigureCanvasAgg(fig)
    for i, g in enumerate(groups):
        ax = fig.add_subplot(1, len(groups), i + 1)
        for label, (xs, ys, end) in _curves(report, curves, g.id, main.key).items():
            line = ax.plot(xs, ys, marker=".", label=label, color=colours.get(label))[0] if xs else None
            if end is not None:
                ax.plot([end[0]], [end[1]], marker="o", linestyle="", color=colours.get(label),
                        label=None if line else label)
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel(f"{main.label} ({'higher' if main.direction == 'higher' else 'lower'} is better)")
        smoke = ", smoke test: not a result" if is_smoke(report.scale) else ""
        ax.set_title(f"{g.label}: {main.label} vs time ({report.scale}{smoke})", fontsize=9)
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
        else:
            ax.text(0.5, 0.5, "no finished jobs yet", ha="center", va="center", transform=ax.transAxes)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()
