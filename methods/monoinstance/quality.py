"""Quality of the uncertainty stage against ground truth (synthetic scenes only).

* **ARI** (adjusted Rand index, Hubert & Arabie 1985) between predicted global ids and GT instance ids
  over a set of pixels, from the contingency table ``n_ij``:
  ``ARI = (sum_ij C(n_ij, 2) - E) / (0.5 (sum_i C(a_i, 2) + sum_j C(b_j, 2)) - E)``,
  ``E = sum_i C(a_i, 2) sum_j C(b_j, 2) / C(n, 2)``. 1 = identical partitions, ~0 = chance. Predicted
  id 0 ("none") counts as one label. Equal trivial partitions (both one label) give 1.
* **Purity**: fraction of pixels whose predicted instance's majority GT id equals their GT id.
"""

from __future__ import annotations

import numpy as np


def _contingency(pred: np.ndarray, gt: np.ndarray) -> np.ndarray:
    _, pi = np.unique(pred.ravel(), return_inverse=True)
    _, gi = np.unique(gt.ravel(), return_inverse=True)
    table = np.zeros((pi.max() + 1, gi.max() + 1), dtype=np.int64)
    np.add.at(table, (pi, gi), 1)
    return table


def adjusted_rand_index(pred: np.ndarray, gt: np.ndarray) -> float:
    """ARI of two labelings of the same pixels (any shapes with equal size); NaN if fewer than 2 pixels."""
    pred, gt = np.asarray(pred).ravel(), np.asarray(gt).ravel()
    if pred.size != gt.size:
        raise ValueError(f"pred and gt sizes differ: {pred.size} vs {gt.size}")
    n = pred.size
    if n < 2:
        return float("nan")
    t = _contingency(pred, gt).astype(np.float64)

    def c2(x):
        return x * (x - 1) / 2.0

    sum_ij = c2(t).sum()
    sa, sb = c2(t.sum(1)).sum(), c2(t.sum(0)).sum()
    expected = sa * sb / c2(float(n))
    maxi = 0.5 * (sa + sb)
    if maxi == expected:
        return 1.0
    return float((sum_ij - expected) / (maxi - expected))


def purity(pred: np.ndarray, gt: np.ndarray) -> float:
    """Fraction of pixels whose predicted label's majority GT label is their own GT label."""
    pred, gt = np.asarray(pred).ravel(), np.asarray(gt).ravel()
    if pred.size == 0:
        return float("nan")
    t = _contingency(pred, gt)
    return float(t.max(1).sum() / pred.size)
