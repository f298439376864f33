"""Capture effects on the RGB images (float32 in [0, 1])."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from bench.data.scene import Scene

from ._params import param
from .registry import register


@dataclass(frozen=True)
class SensorNoiseParams:
    sigma: float = param(2.0, "float", lo=0.0, hi=64.0, unit="8-bit levels", doc="std of the Gaussian noise / 255")


@register("sensor_noise", SensorNoiseParams, needs=("images",))
def sensor_noise(scene: Scene, p: SensorNoiseParams, rng: np.random.Generator) -> None:
    """Additive Gaussian sensor noise on the images.

    Models: photon / read noise of a real camera (the renderer's images are noise-free).
    ``I' = clip(I + sigma / 255 * N(0, 1), 0, 1)``, independent per pixel, channel and view.

    Parameters: sigma (8-bit intensity levels).
    """
    img = scene.images
    for v in range(img.shape[0]):
        noise = rng.standard_normal(img.shape[1:]) * (p.sigma / 255.0)
        img[v] = np.clip(img[v].astype(np.float64) + noise, 0.0, 1.0).astype(np.float32)
    return None


@dataclass(frozen=True)
class ExposureParams:
    gain: tuple[float, float] = param(
        (0.8, 1.2), "range", lo=0.0, lo_open=True, hi=10.0, unit="1", doc="per-view gain g_v, drawn uniformly"
    )


@register("exposure_change", ExposureParams, needs=("images",))
def exposure_change(scene: Scene, p: ExposureParams, rng: np.random.Generator) -> dict[str, Any]:
    """Per-view exposure (gain) change.

    Models: auto-exposure / white-level changes between the images of a hand-held capture, which
    break brightness constancy across views.

    ``I' = clip(g_v I, 0, 1)`` with ``g_v ~ U(gain)``, one gain per view for all pixels and channels.

    Parameters: gain (range, unitless, > 0).
    """
    img = scene.images
    gains = []
    for v in range(img.shape[0]):
        g = float(rng.uniform(*p.gain))
        img[v] = np.clip(img[v].astype(np.float64) * g, 0.0, 1.0).astype(np.float32)
        gains.append(g)
    return {"gain": gains}
