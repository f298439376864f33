"""The scene datasheet: measured properties of a GT-carrying scene beside published real-data anchors.

Public API::

    compute_datasheet(scene, gt_mesh=None) -> dict        # JSON-able, stable keys (sheet.py)
    render_card(sheet) -> str                             # markdown card (card.py)
    write_card(sheet, path.md) -> [path.md, path.png]     # card + plot, atomically
    anchors_for(profile, dataset) -> (profile used, {key: Anchor}, caveats)   (anchors.py)

Modules: ``regions`` (per-pixel regions), ``priors`` (depth / normal prior error), ``photometric``
(image-gradient content), ``capture`` (views per surface point, baselines, distances), ``thin``
(thin-part widths), ``anchors`` (the published figures and their sources), ``card`` (markdown + plot),
``source`` (what ``bench scenes card`` loads). Every field is defined in ``docs/datasheet.md``.
"""

from bench.data.datasheet.anchors import Anchor, anchors_for
from bench.data.datasheet.card import CARD_NAME, render_card, write_card
from bench.data.datasheet.sheet import compute_datasheet

__all__ = ["CARD_NAME", "Anchor", "anchors_for", "compute_datasheet", "render_card", "write_card"]
