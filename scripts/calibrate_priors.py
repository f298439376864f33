"""Calibrate the simulated prior profiles against their real networks' published figures.

For every profile of ``bench.data.synth.effects.PRIOR_PROFILES`` (sim-omnidata, sim-metric3d-v2,
sim-geowizard) and every calibration scene, the scene is rendered once without effects, the profile
is applied exactly as ``bench scenes make`` applies it (first effect, effects stream
``default_rng([seed, 1])``), and the prior statistics of the datasheet (``bench.data.datasheet``:
depth AbsRel / delta1 after per-view least-squares scale + shift, mean over views; normal angle
statistics pooled over pixels; both per region) are printed beside the published anchors of the
profile's network (``bench.data.datasheet.anchors``). A Replica scene is compared with the ScanNet
figures (no Replica figure is published).

With ``--fit`` the knobs of ``FIT_PLAN`` are re-fitted first, one after the other by bisection on the
mean over the scenes, two rounds (each knob against one anchor; the others are fixed by the profile's
documented character), and the fitted values are printed to be written into profiles.py by hand.
The knob-to-anchor pairing is the calibration procedure of docs/effects.md ("Calibration").

Usage (from the repository root; about 1 min without --fit, 20-30 min with it, on 2 cores):
    python scripts/calibrate_priors.py [--scenes scannet_like_0,scannet_like_1,replica_like_0]
        [--profiles sim-omnidata,...] [--scale small] [--fit]
(``--profiles sim-omnidata-legacy,...`` measures the legacy profiles against the same anchors.)
"""

from __future__ import annotations

import argparse
import copy
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from bench.data.datasheet.anchors import Anchor, anchors_for
from bench.data.datasheet.priors import depth_prior_stats, normal_prior_stats
from bench.data.datasheet.regions import REGION_NAMES, compute_regions
from bench.data.scene import Scene
from bench.data.synth.effects import PRIOR_PROFILES, apply_effects
from bench.data.synth.make import make_scene
from bench.data.synth.recipe import load_recipe

ROOT = Path(__file__).resolve().parents[1]
SCENES = ("scannet_like_0", "scannet_like_1", "replica_like_0")
PROFILES = ("sim-omnidata", "sim-metric3d-v2", "sim-geowizard")
ROUNDS, ITERATIONS = 2, 7
LEGACY_SUFFIX = "-legacy"  # a legacy profile is compared with its network's anchors too


@dataclass(frozen=True)
class Knob:
    """One fitted parameter: the ``occurrence``-th effect named ``effect`` in the profile, its ``param``,
    bisected in ``bracket`` until the anchor ``key`` (its midpoint, for a range) is met; ``increasing``:
    the statistic grows with the parameter."""

    effect: str
    occurrence: int
    param: str
    key: str
    bracket: tuple[float, float]
    increasing: bool


# Each knob stands for one real error and is fitted to the one anchor it mostly moves (docs/effects.md):
FIT_PLAN = (
    # gross failures (the tail beyond the 25 % of delta1) -> delta1
    Knob("prior_failure_regions", 0, "count", "depth_prior.all.delta1", (0.0, 10.0), increasing=False),
    # the smooth per-image bend of the depth (the body of the error) -> AbsRel
    Knob("lowfreq_warp", 0, "amplitude", "depth_prior.all.abs_rel", (0.0, 0.5), increasing=True),
    # the normal network's smooth per-image error (planes) -> share within 11.25 deg
    Knob("normal_network", 0, "lowfreq_deg", "normal_prior.all.within_11_25", (0.0, 20.0), increasing=False),
    # the normal prior's heavy tail (clutter, GT-normal noise of the real data) -> mean angle
    Knob("prior_failure_regions", 1, "count", "normal_prior.all.mean_deg", (0.0, 20.0), increasing=True),
)

ROWS = (  # (datasheet key, label, scale for printing)
    ("depth_prior.all.abs_rel", "depth AbsRel %", 100.0),
    ("depth_prior.all.delta1", "depth delta1 %", 100.0),
    ("normal_prior.all.mean_deg", "normal mean deg", 1.0),
    ("normal_prior.all.median_deg", "normal median deg", 1.0),
    ("normal_prior.all.within_11_25", "normal <11.25 %", 100.0),
    ("normal_prior.all.within_22_5", "normal <22.5 %", 100.0),
    ("normal_prior.all.within_30", "normal <30 %", 100.0),
)


def render(name: str, scale: str) -> tuple[Scene, int]:
    """The scene of recipe ``configs/scenes/NAME.yaml`` with exact priors, and its seed."""
    recipe = load_recipe(ROOT / "configs" / "scenes" / f"{name}.yaml")
    bare = replace(recipe, raw={**recipe.raw, "effects": []}, effects=[])
    scene, _ = make_scene(bare, scale)
    return scene, recipe.seed


def prior_stats(scene: Scene, effects: list[dict[str, Any]], seed: int) -> dict[str, float]:
    """Apply ``effects`` to a copy of ``scene`` from the effects stream; flat datasheet prior statistics
    (``"depth_prior.<region>.<stat>"``, ``"normal_prior.<region>.<stat>"``) and region shares."""
    s = copy.deepcopy(scene)
    apply_effects(s, effects, np.random.default_rng([seed, 1]), where="calibrate_priors")
    regions = compute_regions(s)
    parts = regions.partition()
    out: dict[str, float] = {f"regions.{k}": v for k, v in regions.fractions().items()}
    gt_depth = np.asarray(s.gt_depth)
    for group, stats in (
        ("depth_prior", depth_prior_stats(np.asarray(s.mono_depth), gt_depth, parts)),
        ("normal_prior", normal_prior_stats(np.asarray(s.mono_normal), np.asarray(s.gt_normal), parts)),
    ):
        for region, values in stats.items():
            for k, v in values.items():
                if isinstance(v, (int, float)) and v is not None:
                    out[f"{group}.{region}.{k}"] = float(v)
    return out


def mean_stats(scenes: dict[str, tuple[Scene, int]], effects: list[dict[str, Any]]) -> dict[str, float]:
    per = [prior_stats(scene, effects, seed) for scene, seed in scenes.values()]
    return {k: float(np.mean([p[k] for p in per if k in p])) for k in per[0]}


def target(anchor: Anchor) -> float:
    return 0.5 * (anchor.low + anchor.high)


def knob_entry(effects: list[dict[str, Any]], knob: Knob) -> dict[str, Any]:
    found = [e for e in effects if e["name"] == knob.effect]
    if len(found) <= knob.occurrence:
        raise SystemExit(f"profile has no effect {knob.effect!r} number {knob.occurrence} to fit")
    return found[knob.occurrence]


def fit(profile: str, scenes: dict[str, tuple[Scene, int]]) -> list[dict[str, Any]]:
    """``FIT_PLAN`` applied to a copy of the profile; returns the fitted effect list."""
    effects = copy.deepcopy(PRIOR_PROFILES[profile])
    _, anchors, _ = anchors_for(profile, "scannet")
    for rnd in range(ROUNDS):
        for knob in FIT_PLAN:
            if knob.key not in anchors:
                continue
            entry, goal = knob_entry(effects, knob), target(anchors[knob.key])
            lo, hi = knob.bracket
            for _ in range(ITERATIONS):
                entry[knob.param] = 0.5 * (lo + hi)
                below = mean_stats(scenes, effects)[knob.key] < goal
                lo, hi = (entry[knob.param], hi) if below == knob.increasing else (lo, entry[knob.param])
            entry[knob.param] = round(0.5 * (lo + hi), 3)
            print(f"  {profile} round {rnd}: {knob.effect}[{knob.occurrence}].{knob.param} = {entry[knob.param]}", flush=True)
    return effects


def report(profile: str, effects: list[dict[str, Any]], scenes: dict[str, tuple[Scene, int]]) -> None:
    """Print measured vs anchor per scene and the mean, then the error by region."""
    _, anchors, caveats = anchors_for(profile.removesuffix(LEGACY_SUFFIX), "scannet")
    per = {name: prior_stats(scene, effects, seed) for name, (scene, seed) in scenes.items()}
    names = list(per)
    print(f"\n## {profile}")
    print("| statistic | " + " | ".join(names) + " | mean | anchor | source |")
    print("|---|" + "---|" * (len(names) + 3))
    for key, label, k in ROWS:
        vals = [per[n].get(key) for n in names]
        cells = ["-" if v is None else f"{k * v:.1f}" for v in vals]
        mean = np.mean([v for v in vals if v is not None]) if any(v is not None for v in vals) else None
        a = anchors.get(key)
        anchor = "-" if a is None else (f"{k * a.low:.1f}" if a.low == a.high else f"{k * a.low:.1f}-{k * a.high:.1f}")
        print(f"| {label} | " + " | ".join(cells) + f" | {'-' if mean is None else f'{k * mean:.1f}'} | {anchor} | "
              f"{'assumed: no anchor' if a is None else a.cite} |")
    print("\nby region (mean over scenes) | share of pixels % | depth AbsRel % | depth delta1 % | normal mean deg | normal median deg |")
    print("|---|---|---|---|---|---|")
    for region in REGION_NAMES:
        keys = (f"regions.{region}", f"depth_prior.{region}.abs_rel", f"depth_prior.{region}.delta1",
                f"normal_prior.{region}.mean_deg", f"normal_prior.{region}.median_deg")
        means = [np.mean([per[n][k] for n in names if k in per[n]]) for k in keys]
        share, absrel, delta1, nmean, nmed = means
        print(f"| {region} | {100 * share:.1f} | {100 * absrel:.1f} | {100 * delta1:.1f} | {nmean:.1f} | {nmed:.1f} |")
    for c in caveats:
        print(f"  note: {c}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--profiles", default=",".join(PROFILES))
    parser.add_argument("--scale", default="small")
    parser.add_argument("--fit", action="store_true", help="re-fit the FIT_PLAN knobs first and print them")
    args = parser.parse_args()
    scenes = {name: render(name, args.scale) for name in args.scenes.split(",")}
    for profile in args.profiles.split(","):
        if profile not in PRIOR_PROFILES:
            raise SystemExit(f"unknown profile {profile!r} (known: {', '.join(PRIOR_PROFILES)})")
        effects = fit(profile, scenes) if args.fit else PRIOR_PROFILES[profile]
        report(profile, effects, scenes)


if __name__ == "__main__":
    main()
