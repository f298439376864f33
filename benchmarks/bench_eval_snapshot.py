"""Benchmark: evaluating one snapshot under the ScanNet and Replica protocols, as a `bench run` worker does.

Run:  python benchmarks/bench_eval_snapshot.py [--scale small] [--repeats 3] [--threads 1]

For scannet_like_0 (ScanNet protocol) and replica_like_0 (Replica protocol) it times
``bench.evaluate.evaluate_snapshot`` (best of ``--repeats``; the GT side is prepared once per scene and
cached, as in a job, and its one-time cost is printed separately) on two predictions that need no
training: the GT mesh subdivided to 10 cm edges (a finely tessellated surface) and shifted by
2 cm ("clean", like a converged SDF), and the same mesh plus 30k small triangles scattered through the
room ("floaters", like a no-prior SDF's ~50k junk faces: nearest neighbours from far away and many
fusion blocks dominate). Prints seconds per snapshot and the metrics.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh
import trimesh.remesh

from bench.data.datasets import load_dataset
from bench.evaluate import evaluate_snapshot
from methods.base import Snapshot


def floaters(mesh: trimesh.Trimesh, n: int, seed: int = 0) -> trimesh.Trimesh:
    """``mesh`` plus ``n`` ~3 cm triangles at uniform positions in its bounds."""
    rng = np.random.default_rng(seed)
    centres = rng.uniform(mesh.bounds[0], mesh.bounds[1], (n, 3))
    tri = centres[:, None, :] + rng.normal(scale=0.03, size=(n, 3, 3))
    v = np.concatenate([mesh.vertices, tri.reshape(-1, 3)])
    f = np.concatenate([mesh.faces, len(mesh.vertices) + np.arange(3 * n).reshape(n, 3)])
    return trimesh.Trimesh(v, f, process=False)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scale", default="small")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1, help="threads for torch / open3d / scipy (a worker has 1)")
    args = ap.parse_args()
    from bench.executors.base import set_job_threads

    set_job_threads(args.threads)
    print(f"threads: {args.threads}  scale: {args.scale}")
    for scene_name, protocol in (("scannet_like_0", "scannet"), ("replica_like_0", "replica")):
        scene = load_dataset(scene_name, args.scale)
        gt = scene.load_gt_mesh()
        v, f = trimesh.remesh.subdivide_to_size(gt.vertices, gt.faces, max_edge=0.1)
        clean = trimesh.Trimesh(v + [0.02, 0.0, 0.0], f, process=False)
        for case, mesh in (("clean", clean), ("floaters", floaters(clean, 30_000))):
            snap = Snapshot(fraction=1.0, iterations=0, seconds=0.0, mesh=mesh)
            t = time.perf_counter()
            metrics = evaluate_snapshot(snap, scene, protocol, args.scale, seed=0)  # first call also prepares the GT
            first = time.perf_counter() - t
            best = float("inf")
            for _ in range(args.repeats):
                t = time.perf_counter()
                evaluate_snapshot(snap, scene, protocol, args.scale, seed=0)
                best = min(best, time.perf_counter() - t)
            shown = {k: round(v, 3) for k, v in metrics.items()}
            print(f"{protocol:8s} {case:9s} {len(mesh.faces):7d} faces: {best:.3f} s per snapshot "
                  f"(first call with the GT side: {first:.3f} s)  {shown}")


if __name__ == "__main__":
    main()
