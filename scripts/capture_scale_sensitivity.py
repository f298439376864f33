"""How well does a room scene's capture pin down the room's scale? The capture geometry of one room.

The per-view scale-and-shift-invariant depth loss accepts a room shrunk about the cameras; only the
images (colour seen from several places) hold its size. This script makes a room recipe in memory at
``--scale`` (``--preset`` swaps the room preset, e.g. ``scannet-legacy`` for the scene as first
generated) and reports:

* scale sensitivity: the room (all GT geometry) shrunk by ``--k`` about the room's centre, cameras
  fixed: how far each view's own GT pixels move in that view (median / 90th percentile, pixels; walls
  alone and every surface); the same about the cameras' centroid (the centre a scale-and-shift-invariant
  depth loss shrinks towards, scripts/shrink_parallax.py);
* camera-to-surface distance of every GT pixel (ray length, metres: median, 10 / 90 %);
* overlap of consecutive frames: the share of a view's GT surface that the next view sees;
* views per GT surface point: ``--points`` points sampled uniformly on the GT mesh inside the room,
  seen by a view when in its frame and not behind its GT depth (metrics.culling.views_seeing);
* baseline / depth of the view pairs that see a point: every pair (median) and each point's widest pair
  (median over points);
* each object: the views showing at least ``--min-pixels`` of it and the azimuth span of the
  directions from the object to those cameras (360 - the largest gap; > 90 deg = seen from two sides).

Usage:
    PYTHONPATH=. .venv/bin/python scripts/capture_scale_sensitivity.py scannet_like_0 [replica_like_0 ...]
        [--preset scannet-legacy] [--scale small] [--k 0.95] [--points 20000] [--plot topdown.png]
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np


def shrink_displacement(scene: Any, centre: np.ndarray, k: float, views: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """Pixel displacement of every view's own GT pixels when the room shrinks by ``k`` about ``centre``
    (world metres) and the cameras stay: {"walls": (M,), "all": (P,)} pixels."""
    from metrics.camera import backproject, project

    walls = [i for i, info in scene.instances.items() if info.category == "wall"]
    out: dict[str, list[np.ndarray]] = {"walls": [], "all": []}
    for v in (range(scene.num_views) if views is None else views):
        valid = scene.gt_depth[v] > 0
        X = backproject(scene.gt_depth[v].astype(np.float64), scene.intrinsics[v], scene.cam_to_world[v])[valid]
        ua, va, _ = project(X, scene.intrinsics[v], scene.cam_to_world[v])
        ub, vb, _ = project(centre + k * (X - centre), scene.intrinsics[v], scene.cam_to_world[v])
        d = np.hypot(ub - ua, vb - va)
        out["all"].append(d)
        out["walls"].append(d[np.isin(scene.gt_instance[v][valid], walls)])
    return {key: np.concatenate(parts) for key, parts in out.items()}


def surface_distances(scene: Any) -> np.ndarray:
    """(P,) distance from the camera centre to the surface of every GT pixel of every view, metres."""
    from metrics.camera import pixel_rays

    out = []
    for v in range(scene.num_views):
        valid = scene.gt_depth[v] > 0
        rays = pixel_rays(scene.intrinsics[v], scene.height, scene.width)[valid]
        out.append(np.linalg.norm(rays, axis=1) * scene.gt_depth[v][valid])
    return np.concatenate(out)


def consecutive_overlap(scene: Any, stride: int = 4) -> np.ndarray:
    """(N - 1,) share of view v's GT surface pixels (every ``stride``-th) that view v + 1 sees: how much
    consecutive frames of the capture overlap."""
    from metrics.camera import backproject
    from metrics.culling import views_seeing

    out = []
    for v in range(scene.num_views - 1):
        valid = scene.gt_depth[v] > 0
        X = backproject(scene.gt_depth[v].astype(np.float64), scene.intrinsics[v], scene.cam_to_world[v])[valid][::stride]
        nxt = slice(v + 1, v + 2)
        out.append(views_seeing(X, scene.intrinsics[nxt], scene.cam_to_world[nxt], scene.height, scene.width, scene.gt_depth[nxt], tol=0.03).mean())
    return np.asarray(out)


def sample_room_surface(mesh: Any, room_size: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """(M, 3) points uniform on the GT mesh's area, keeping those inside the room box (the shell's outer
    faces never face a camera), M <= n."""
    import trimesh

    points, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    inside = np.all((points >= -1e-3) & (points <= np.asarray(room_size) + 1e-3), axis=1)
    return np.asarray(points[inside])


def pair_ratios(centres: np.ndarray, points: np.ndarray, seen: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Baseline / depth of the view pairs that see each point.

    Args:
        centres: (N, 3) camera centres; points: (P, 3); seen: (N, P) bool.

    Returns:
        (all pairs' ratios, each point's widest pair's ratio (points seen twice or more)): baseline
        |C_i - C_j| over the mean distance of the two cameras to the point.
    """
    ratios, widest = [], []
    for p in np.flatnonzero(seen.sum(0) >= 2):
        c = centres[seen[:, p]]
        i, j = np.triu_indices(len(c), 1)
        dist = np.linalg.norm(c - points[p], axis=1)
        r = np.linalg.norm(c[i] - c[j], axis=1) / (0.5 * (dist[i] + dist[j]))
        ratios.append(r)
        widest.append(r.max())
    return (np.concatenate(ratios) if ratios else np.zeros(0)), np.asarray(widest)


def azimuth_span_deg(azimuths: np.ndarray) -> float:
    """The smallest arc (degrees) holding all ``azimuths`` (radians): 360 - the largest gap between them."""
    if len(azimuths) < 2:
        return 0.0
    a = np.sort(np.mod(azimuths, 2 * np.pi))
    gaps = np.diff(np.concatenate([a, a[:1] + 2 * np.pi]))
    return float(np.degrees(2 * np.pi - gaps.max()))


def object_sides(scene: Any, min_pixels: int) -> dict[str, tuple[int, float]]:
    """Each non-background object: (views showing >= ``min_pixels`` of it, azimuth span in degrees of the
    directions from its visible points' centroid to those cameras)."""
    from metrics.camera import backproject

    found: dict[int, list[float]] = {i: [] for i, info in scene.instances.items() if not info.is_background}
    for v in range(scene.num_views):
        X = backproject(scene.gt_depth[v].astype(np.float64), scene.intrinsics[v], scene.cam_to_world[v])
        for i in found:
            mask = scene.gt_instance[v] == i
            if mask.sum() >= min_pixels:
                d = scene.cam_to_world[v, :3, 3] - X[mask].mean(axis=0)
                found[i].append(float(np.arctan2(d[1], d[0])))
    return {scene.instances[i].name: (len(az), azimuth_span_deg(np.asarray(az))) for i, az in found.items()}


def capture_report(scene: Any, mesh: Any, k: float, n_points: int, min_pixels: int) -> dict[str, Any]:
    """Every number of the module docstring for one made scene (``make_scene``'s scene and GT mesh)."""
    from metrics.culling import views_seeing

    room = np.asarray(scene.metadata["layout"]["room_size_m"], dtype=float)
    centres = scene.cam_to_world[:, :3, 3]
    about_room = shrink_displacement(scene, room / 2, k)
    about_cams = shrink_displacement(scene, centres.mean(axis=0), k)
    dist = surface_distances(scene)
    points = sample_room_surface(mesh, room, n_points)
    seen = views_seeing(points, scene.intrinsics, scene.cam_to_world, scene.height, scene.width, scene.gt_depth, tol=0.03)
    counts = seen.sum(axis=0)
    ratios, widest = pair_ratios(centres, points, seen)
    return {
        "views": scene.num_views,
        "image": f"{scene.width}x{scene.height}",
        "shrink_room_centre_walls_px": (np.median(about_room["walls"]), np.percentile(about_room["walls"], 90)),
        "shrink_room_centre_all_px": (np.median(about_room["all"]), np.percentile(about_room["all"], 90)),
        "shrink_camera_centroid_walls_px": (np.median(about_cams["walls"]), np.percentile(about_cams["walls"], 90)),
        "camera_to_surface_m": tuple(np.percentile(dist, [50, 10, 90])),
        "surface_within_1_3m": float(np.mean((dist >= 1.0) & (dist <= 3.0))),
        "consecutive_frames_overlap": tuple(np.percentile(consecutive_overlap(scene), [50, 10, 90])),
        "views_per_point": tuple(np.percentile(counts, [50, 10, 90])),
        "views_per_seen_point": tuple(np.percentile(counts[counts > 0], [50, 10, 90])),
        "points_unseen": float(np.mean(counts == 0)),
        "points_seen_3plus": float(np.mean(counts >= 3)),
        "pair_baseline_over_depth": tuple(np.percentile(ratios, [50, 10, 90])) if ratios.size else (0.0, 0.0, 0.0),
        "widest_pair_baseline_over_depth": tuple(np.percentile(widest, [50, 10, 90])) if widest.size else (0.0, 0.0, 0.0),
        "objects": object_sides(scene, min_pixels),
    }


def plot_topdown(scene: Any, ax: Any, title: str) -> None:
    """Top-down view of a made room: the room's outline, the GT surface points of the furniture seen by
    the views (one colour per object), camera centres in capture order with their viewing directions."""
    from metrics.camera import backproject

    sx, sy, _ = scene.metadata["layout"]["room_size_m"]
    ax.plot([0, sx, sx, 0, 0], [0, 0, sy, sy, 0], "k-", lw=1)
    colours = {i: np.random.default_rng(i).uniform(0.1, 0.8, 3) for i, info in scene.instances.items() if not info.is_background}
    for v in range(scene.num_views):
        X = backproject(scene.gt_depth[v].astype(np.float64), scene.intrinsics[v], scene.cam_to_world[v])
        for i, colour in colours.items():
            pts = X[scene.gt_instance[v] == i][::3]
            ax.scatter(pts[:, 0], pts[:, 1], s=0.3, color=colour)
    for i, colour in colours.items():
        ax.plot([], [], "s", color=colour, label=scene.instances[i].name)
    c, f = scene.cam_to_world[:, :3, 3], scene.cam_to_world[:, :3, 2]
    ax.plot(c[:, 0], c[:, 1], "-", color="0.5", lw=0.6)
    ax.quiver(c[:, 0], c[:, 1], f[:, 0], f[:, 1], angles="xy", scale=14, width=0.004, color="tab:blue")
    ax.plot(c[:1, 0], c[:1, 1], "o", color="tab:green")
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=6, loc="upper left", bbox_to_anchor=(1.0, 1.0), markerscale=1.5, frameon=False)


def main() -> None:
    from bench.data.datasets import recipe_path
    from bench.data.synth.make import make_scene
    from bench.data.synth.recipe import load_recipe, parse_recipe

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+", help="room recipe names (configs/scenes) or YAML paths")
    ap.add_argument("--preset", default=None, help="another room preset, e.g. scannet-legacy")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--k", type=float, default=0.95, help="shrink factor")
    ap.add_argument("--points", type=int, default=20000, help="GT surface points sampled")
    ap.add_argument("--min-pixels", type=int, default=20, help="pixels of an object that count as seeing it")
    ap.add_argument("--plot", default=None, help="write a top-down plot of each room (furniture seen, cameras) to this PNG")
    args = ap.parse_args()
    plots = []
    for name in args.scenes:
        recipe = load_recipe(recipe_path(name) if not name.endswith(".yaml") else name)
        if args.preset:
            recipe = parse_recipe({**recipe.raw, "preset": args.preset}, recipe.where(), path=recipe.path)
        scene, mesh = make_scene(recipe, scale=args.scale)
        report = capture_report(scene, mesh, args.k, args.points, args.min_pixels)
        plots.append((scene, f"{name} ({recipe.raw.get('preset', recipe.format)}, {args.scale}): wall px moved by a 5 % shrink, "
                             f"median {report['shrink_room_centre_walls_px'][0]:.2f}"))
        print(f"== {name} preset {recipe.raw.get('preset', recipe.format)} scale {args.scale}: {report['views']} views {report['image']}, shrink k = {args.k}")
        for key, value in report.items():
            if key == "objects":
                print("  objects (views >= %d px, azimuth span deg): " % args.min_pixels
                      + ", ".join(f"{n} {c} / {s:.0f}" for n, (c, s) in value.items()))
            elif isinstance(value, tuple):
                print(f"  {key:36s} " + " / ".join(f"{x:.3g}" for x in value))
            elif key not in ("views", "image"):
                print(f"  {key:36s} {value:.3g}")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(1, len(plots), figsize=(5.5 * len(plots), 5), squeeze=False)
        for ax, (scene, title) in zip(axes[0], plots):
            plot_topdown(scene, ax, title)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=80, bbox_inches="tight")
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
