"""Evaluation metrics of the benchmark (standalone: imports neither ``methods`` nor ``bench``).

Definitions are documented once, in each module's docstring and in ``docs/metrics.md``.
"""

from metrics.depth import DepthMetrics, align_depth, depth_metrics
from metrics.image import ImageScores, psnr, quantize_8bit, ssim
from metrics.mesh import MeshMetrics, clean_mesh, evaluate_mesh_pair, point_metrics, sample_mesh_surface
from metrics.nn import nearest_neighbor, nearest_neighbor_bruteforce
from metrics.uncertainty import UncertaintyMetrics, ause, region_masks, sparsification_curve, spearman, uncertainty_metrics

__all__ = [
    "DepthMetrics", "align_depth", "depth_metrics",
    "ImageScores", "psnr", "quantize_8bit", "ssim",
    "MeshMetrics", "clean_mesh", "evaluate_mesh_pair", "point_metrics", "sample_mesh_surface",
    "nearest_neighbor", "nearest_neighbor_bruteforce",
    "UncertaintyMetrics", "ause", "region_masks", "sparsification_curve", "spearman", "uncertainty_metrics",
]
