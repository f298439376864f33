"""Where MonoSDF's geometric-init sphere starts relative to what the views see, per scene.

An indoor MonoSDF run starts from an inside-out sphere of radius ``init_radius`` (normalised units) about
the scene's centre: every camera ray first meets that sphere. This script casts every pixel's ray onto
the sphere and compares the distance with the GT surface's: the share of pixels whose sphere point lies
*behind* the GT surface (the field has to pull its surface in towards the cameras) and by how much, and
the same for the bounding sphere (where the SDF is clamped: a surface every ray ends on). It also prints
the room box, the camera extent and MonoSDF's own normalisation of the scene (its unit: half of the
cameras' largest extent + 3 m), which ``init_radius: auto`` converts MonoSDF's bias from, and the share of
the GT surface's area beyond the bounding sphere in the scene's normalisation and in MonoSDF's (a surface
the clamped SDF cannot represent).

Usage:
    .venv/bin/python scripts/initial_sphere_placement.py SCENE [SCENE ...] [--scale small]
        [--init-radius auto|R] [--bounding-sphere 1.0] [--meshes MESH.ply ...] [--plot PLAN.png]

``--meshes``: reconstructed meshes of the (last) scene, world metres (``bench study convergence`` writes every
snapshot to ``OUT/meshes/``): the area-weighted distance of their faces from the scene's centre (10 / 50 /
90 %) and the share of their area lying on the bounding sphere (within 2 % of its radius), where a run
that never formed the room leaves its surface.

SCENE is a recipe name (made or taken from the cache) or a dataset folder. Distances are Euclidean along
the ray, metres; GT z-depth is converted with the ray's z component (OpenCV camera axes).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import NamedTuple

import numpy as np


def sphere_minus_surface(scene, centre: np.ndarray, unit_m: float, radius: float) -> tuple[np.ndarray, int]:
    """Per GT pixel (views whose camera stands inside the sphere, pixels with GT depth > 0, concatenated): the
    distance along its ray to the sphere of ``radius`` (normalised units) about ``centre`` (world, metres)
    minus the distance to the GT surface, metres (> 0: the sphere lies behind the surface); and the number
    of views left out because their camera stands outside the sphere (``unit_m``: metres per unit)."""
    from methods.monosdf.rays import camera_rays, sphere_exit_distance

    out, outside = [], 0
    for v in range(len(scene.cam_to_world)):
        K, c2w = scene.intrinsics[v], scene.cam_to_world[v]
        o = (c2w[:3, 3] - centre) / unit_m
        if np.linalg.norm(o) >= radius:
            outside += 1  # the camera stands outside this sphere: no inside-out start for its rays
            continue
        d_world, norm = camera_rays(K, c2w, scene.height, scene.width)
        t_sphere = sphere_exit_distance(o, d_world, radius) * unit_m  # the trainer's ray set-up (build_rays)
        z = np.asarray(scene.gt_depth[v], dtype=np.float64).reshape(-1)
        ok = z > 0
        out.append(t_sphere[ok] - z[ok] * norm[ok])  # z-depth -> distance along the ray (d_cam has z = 1)
    return (np.concatenate(out) if out else np.zeros(0)), outside


def area_beyond(mesh, centre: np.ndarray, radius_m: float) -> float:
    """Share of ``mesh``'s area (world metres) whose faces' centres lie further than ``radius_m`` from
    ``centre`` (3,): the surface a bounding sphere of that radius cannot hold."""
    beyond = np.linalg.norm(mesh.triangles_center - centre, axis=1) > radius_m
    return float(mesh.area_faces[beyond].sum() / mesh.area)


class FloorPlan(NamedTuple):
    """One scene's panel of :func:`floor_plans` (world metres)."""

    name: str
    lines: list[np.ndarray]  # GT surface cut at the centre's height: (2, 2) segments, x / y
    cameras_xy: np.ndarray  # (V, 2) camera positions
    centre_xy: np.ndarray  # (2,) the spheres' centre
    init_radius_m: float
    bounding_radius_m: float


def floor_plans(plans: list[FloorPlan], out: Path) -> None:
    """One panel per scene, world x / y metres: the GT surface cut at the scene centre's height (grey lines),
    the camera positions (blue), the initial sphere (orange) and the bounding sphere (red) at that height."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(plans), figsize=(4.2 * len(plans), 4.5), squeeze=False)
    for ax, (name, lines, cams_xy, c, r_init, r_bound) in zip(axes[0], plans):
        for line in lines:
            ax.plot(line[:, 0], line[:, 1], "-", color="0.4", lw=0.8)
        ax.plot(cams_xy[:, 0], cams_xy[:, 1], "o", color="tab:blue", ms=3, label="cameras")
        for r, colour, label in ((r_init, "tab:orange", f"initial sphere {r_init:.2f} m"), (r_bound, "tab:red", f"bounding sphere {r_bound:.2f} m")):
            ax.add_patch(plt.Circle((float(c[0]), float(c[1])), r, fill=False, color=colour, label=label))
        ax.set_aspect("equal")
        ax.autoscale_view()
        ax.set_title(name)
        ax.set_xlabel("x (m)")
        ax.legend(loc="upper right", fontsize=7)
    axes[0][0].set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main() -> None:
    import trimesh

    from bench.data.datasets import load_dataset
    from bench.data.formats import load_scene
    from bench.data.normalisation import monosdf_indoor_scale_mat, monosdf_indoor_unit_m
    from methods.monosdf.rays import normalisation
    from methods.monosdf.trainer import resolve_init_radius

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scenes", nargs="+")
    ap.add_argument("--scale", default="small")
    ap.add_argument("--init-radius", default="auto", help="'auto' (the default of configs/methods/monosdf.yaml) or a number")
    ap.add_argument("--bounding-sphere", type=float, default=1.0)
    ap.add_argument("--meshes", nargs="*", default=[])
    ap.add_argument("--plot", help="write a floor plan of each scene here (PNG): GT surface, cameras, both spheres")
    args = ap.parse_args()
    plans: list[FloorPlan] = []
    init = args.init_radius if args.init_radius == "auto" else float(args.init_radius)

    for name in args.scenes:
        scene = load_scene(Path(name)) if Path(name).is_dir() else load_dataset(name, args.scale)
        if scene.gt_depth is None:
            raise SystemExit(f"{name}: needs GT depth")
        centre, unit = normalisation(scene)
        radius = resolve_init_radius(init, scene)
        cams = scene.cam_to_world[:, :3, 3]
        extent = cams.max(axis=0) - cams.min(axis=0)
        print(f"== {scene.name} ({scene.source_format}, {scene.num_views} views)")
        if scene.gt_mesh_path is not None:
            gt = trimesh.load(scene.gt_mesh_path, force="mesh", process=False)
            lo, hi = gt.bounds
            print(f"  GT box {np.round(hi - lo, 2)} m; walls / floor / ceiling from the centre: "
                  f"x {centre[0] - lo[0]:.2f} / {hi[0] - centre[0]:.2f}, y {centre[1] - lo[1]:.2f} / {hi[1] - centre[1]:.2f}, "
                  f"z {centre[2] - lo[2]:.2f} / {hi[2] - centre[2]:.2f} m")
            gap = np.minimum(cams.min(axis=0) - lo, hi - cams.max(axis=0))
            print(f"  camera extent {np.round(extent, 2)} m; least gap between the camera extent and the box: "
                  f"x {gap[0]:.2f}, y {gap[1]:.2f} m")
            lines = list(trimesh.intersections.mesh_plane(gt, [0.0, 0.0, 1.0], [0.0, 0.0, float(centre[2])])[:, :, :2])
            plans.append(FloorPlan(scene.name if scene.name == name else f"{scene.name} ({Path(name).name})", lines, cams[:, :2], centre[:2], radius * unit,
                                   args.bounding_sphere * unit))
            mono = monosdf_indoor_scale_mat(scene.cam_to_world)
            for label, c, u in (("this scene's", centre, unit), ("MonoSDF's", mono[:3, 3], mono[0, 0])):
                print(f"  GT surface beyond the bounding sphere in {label} normalisation: "
                      f"{area_beyond(gt, c, args.bounding_sphere * u):.1%} of its area")
        print(f"  scene unit {unit:.3f} m; MonoSDF's unit (largest camera extent + 3 m) / 2 = {monosdf_indoor_unit_m(scene.cam_to_world):.3f} m")
        print(f"  init sphere {radius:.3f} units = {radius * unit:.2f} m; bounding sphere {args.bounding_sphere} = "
              f"{args.bounding_sphere * unit:.2f} m")
        for label, r in (("init sphere", radius), ("bounding sphere", args.bounding_sphere)):
            excess, outside = sphere_minus_surface(scene, centre, unit, r)
            if excess.size == 0:
                print(f"  {label}: every camera stands outside it")
                continue
            b = excess > 0
            q = lambda x: "-" if x.size == 0 else f"{np.median(x):.2f} ({np.quantile(x, 0.1):.2f}-{np.quantile(x, 0.9):.2f})"
            print(f"  {label}: behind the GT surface on {b.mean():.1%} of the pixels, by {q(excess[b])} m "
                  f"(median, 10-90 %); in front on {1 - b.mean():.1%}, by {q(-excess[~b])} m"
                  + (f"; {outside} of {scene.num_views} cameras stand outside it (left out)" if outside else ""))

    if args.plot and plans:
        floor_plans(plans, Path(args.plot))

    for path in args.meshes:
        mesh = trimesh.load(path, force="mesh", process=False)
        area = mesh.area_faces
        dist = np.linalg.norm(mesh.triangles_center - centre, axis=1)
        order = np.argsort(dist)
        cdf = np.cumsum(area[order]) / area.sum()
        p10, p50, p90 = (float(dist[order][np.searchsorted(cdf, q)]) for q in (0.1, 0.5, 0.9))
        on_bound = float(area[dist > 0.98 * args.bounding_sphere * unit].sum() / area.sum())
        print(f"  {path}: {area.sum():.0f} m2; face distance from the centre {p10:.2f} / {p50:.2f} / {p90:.2f} m "
              f"(10 / 50 / 90 %, by area); on the bounding sphere {on_bound:.0%}")


if __name__ == "__main__":
    main()
