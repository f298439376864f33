"""What happens to the SDF in the first optimisation steps? (object scenes lost their surface at once)

Builds a MonoSDF trainer exactly as a study run does (same config resolution, same seed) and prints,
every ``--every`` steps: the minimum SDF over a grid of the extraction cube (``mesh_extent``, or the
bounding sphere), the fraction of that grid inside the surface (SDF < 0), beta, and the step's loss
terms. A surface that vanishes shows as ``min sdf`` crossing 0 and ``inside`` dropping to 0; the
renders then come from the background shell (the bounding-sphere clamp). Used to find
that the DTU-like objects (bounding sphere R = 4) lost the initial ball within 3 steps on seed 1 when the
SDF MLP worked in ``x / R`` coordinates (docs/monosdf.md, "Object scenes").

Usage:
    .venv/bin/python scripts/trace_first_steps.py SCENE SEED [--steps 60] [--every 3] [--exact-priors]
        [--set key=value ...]    (e.g. --set bounding_sphere=4.0 inside_out=false init_radius=0.6 mesh_extent=1.2)
"""

from __future__ import annotations

import argparse


def main() -> None:
    import torch

    from bench.data.config import load_config
    from bench.overrides import parse_overrides
    from bench.study import load_study_scene
    from methods.monosdf.config import MonoSDFConfig
    from methods.monosdf.trainer import MonoSDFTrainer
    from methods.registry import method_config

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="a scene recipe name or a dataset folder")
    ap.add_argument("seed", type=int)
    ap.add_argument("--steps", type=int, default=60)
    ap.add_argument("--every", type=int, default=3)
    ap.add_argument("--scale", default="small")
    ap.add_argument("--exact-priors", action="store_true", help="GT depth and normals as the priors")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="monosdf config overrides")
    ap.add_argument("--grid", type=int, default=41, help="points per axis of the SDF probe grid")
    args = ap.parse_args()

    torch.set_num_threads(1)
    scene = load_study_scene(args.scene, args.scale, "both" if args.exact_priors else "none")
    cfg = load_config(MonoSDFConfig, method_config("monosdf", args.scale, parse_overrides(args.set)), "monosdf config")
    trainer = MonoSDFTrainer(scene, cfg, args.seed)
    half = float(cfg.mesh_extent) if cfg.mesh_extent is not None else float(cfg.bounding_sphere)
    axis = torch.linspace(-half, half, args.grid)
    probe = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    def probe_line(it: int) -> str:
        with torch.no_grad():
            sdf, _, _ = trainer.sdf(probe, with_gradient=False)
        return (f"it {it:5d}  min sdf {float(sdf.min()):+.3f}  inside {float((sdf < 0).float().mean()):.4f}  "
                f"beta {float(trainer.density.beta().detach()):.4f}")

    for it in range(args.steps):
        line = probe_line(it) if it % args.every == 0 else None  # the state before this step
        terms = trainer.step()
        if line is not None:
            print(line + "  " + "  ".join(f"{k} {v:.4f}" for k, v in terms.items() if isinstance(v, float) and k != "beta"), flush=True)
    print(probe_line(args.steps), flush=True)  # the state after the last step

if __name__ == "__main__":
    main()
