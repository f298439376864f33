"""Scene normalisation: the similarity ``scale_mat`` that maps the normalised frame methods work in
(``x_world = scale_mat @ x_normalised``; the region of interest inside the unit sphere) to world metres.

Two rules:

* :func:`sphere_scale_mat`: a given centre and radius (the synthetic scenes' default: a room's
  circumscribed sphere, an object's bounding sphere).
* :func:`monosdf_indoor_scale_mat`: MonoSDF's rule for indoor scans (its ``preprocess/scannet_to_monosdf.py``):
  centre = the middle of the box of the camera positions, one unit = half of (the box's largest extent +
  :data:`MONOSDF_CAMERA_MARGIN_M`), "+3 because we assume each camera sees 1.5 meters forward". Real
  ScanNet scenes in MonoSDF's format carry this ``scale_mat``; so MonoSDF's bounding sphere (1.0) lies about
  1.5 m beyond the outermost cameras and its initial sphere (0.9) a little inside that.
"""

from __future__ import annotations

import numpy as np

MONOSDF_CAMERA_MARGIN_M = 3.0


def sphere_scale_mat(centre: np.ndarray, radius: float) -> np.ndarray:
    """(4, 4) float64 normalised -> world: the unit sphere onto the sphere ``centre`` (3,) m, ``radius`` m."""
    m = np.eye(4)
    m[:3, :3] *= radius
    m[:3, 3] = centre
    return m


def monosdf_indoor_unit_m(cam_to_world: np.ndarray) -> float:
    """Metres per normalised unit under MonoSDF's indoor rule. cam_to_world: (N, 4, 4), metres."""
    positions = np.asarray(cam_to_world, dtype=np.float64)[:, :3, 3]
    return (float((positions.max(axis=0) - positions.min(axis=0)).max()) + MONOSDF_CAMERA_MARGIN_M) / 2.0


def monosdf_indoor_scale_mat(cam_to_world: np.ndarray) -> np.ndarray:
    """(4, 4) float64 normalised -> world under MonoSDF's indoor rule. cam_to_world: (N, 4, 4), metres."""
    positions = np.asarray(cam_to_world, dtype=np.float64)[:, :3, 3]
    centre = (positions.min(axis=0) + positions.max(axis=0)) / 2.0
    return sphere_scale_mat(centre, monosdf_indoor_unit_m(cam_to_world))
