"""The datasheet as a markdown card (one table per section: property | this scene | real-data anchor |
source) and one PNG beside it (normal-prior error CDF per region; views-per-point histogram).

The card is rendered from the datasheet dict alone (:func:`bench.data.datasheet.compute_datasheet`), so a
stored ``meta.json`` can be re-rendered without the scene. Field definitions: ``docs/datasheet.md``.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any, Callable

from bench.data.atomic import atomic_write_bytes, atomic_write_text

from .anchors import NO_ANCHOR, Anchor, anchors_for
from .priors import CDF_STEP_DEG, NORMAL_THRESHOLDS_DEG, within_key
from .regions import REGION_NAMES

CARD_NAME = "datasheet.md"

Fmt = Callable[[float], str]
Rows = list[tuple[str, str, Fmt]]  # (label, datasheet key, formatter)


def _unit(template: str, factor: float = 1.0) -> Fmt:
    """A formatter printing ``factor * x`` with ``template`` (``str.format``)."""
    return lambda x: template.format(factor * x)


_pct = _unit("{:.1f} %", 100.0)
_deg = _unit("{:.1f} deg")
_num = _unit("{:.3g}")
_metres = _unit("{:.2f} m")
_px = _unit("{:.1f} px")
_levels = _unit("{:.2f} levels/px")


def _get(sheet: dict[str, Any], key: str) -> Any:
    node: Any = sheet
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return None
        node = node[part]
    return node


def _anchor_text(a: Anchor, fmt: Fmt) -> str:
    return fmt(a.low) if a.low == a.high else f"{fmt(a.low)} - {fmt(a.high)}"


def _sections(sheet: dict[str, Any]) -> list[tuple[str, str, Rows, str]]:
    """(title, what applies to the whole section, rows, source column of a row without an anchor)."""
    regions = ("all",) + REGION_NAMES
    depth: Rows = [(f"{stat}, {r}", f"depth_prior.{r}.{key}", _pct) for r in regions for stat, key in (("AbsRel", "abs_rel"), ("delta1", "delta1"))]
    normal: Rows = [(f"{label}, all", f"normal_prior.all.{key}", fmt) for label, key, fmt in
                    (("mean angle", "mean_deg", _deg), ("median angle", "median_deg", _deg))]
    normal += [(f"within {t:g} deg, all", f"normal_prior.all.{within_key(t)}", _pct) for t in NORMAL_THRESHOLDS_DEG]
    normal += [(f"{label}, {r}", f"normal_prior.{r}.{key}", fmt) for r in REGION_NAMES for label, key, fmt in
               (("mean angle", "mean_deg", _deg), ("median angle", "median_deg", _deg), ("within 11.25 deg", "within_11_25", _pct))]
    surfaces = ("wall", "floor", "ceiling", "objects")
    photo: Rows = [(f"RMS gradient, {s}", f"photometric.gradient_rms_levels.{s}", _levels) for s in surfaces]
    photo += [(f"gradient energy, {s}", f"photometric.gradient_energy.{s}", _num) for s in surfaces]
    photo += [("textureless share of wall + ceiling", "photometric.textureless_fraction_wall_ceiling", _pct)]
    capture: Rows = [("views", "capture.views", _num),
                     ("surface facing a camera in its image but hidden in every view", "capture.frac_hidden", _pct),
                     ("views per observed point, 10th pct", "capture.views_per_point.p10", _num),
                     ("views per observed point, median", "capture.views_per_point.median", _num),
                     ("views per observed point, 90th pct", "capture.views_per_point.p90", _num),
                     ("observed points seen by < 2 views", "capture.frac_single_view", _pct),
                     ("baseline / depth, median of per-point median", "capture.baseline_depth_ratio.median_of_median", _num),
                     ("baseline / depth, median of per-point max", "capture.baseline_depth_ratio.median_of_max", _num),
                     ("camera-to-surface distance, median", "capture.median_distance_m", _metres)]
    return [
        ("Regions", "share of the valid GT pixels (a partition: thin > silhouette > planar_background / objects)",
         [(r, f"regions.{r}", _pct) for r in REGION_NAMES], "-"),
        ("Depth prior", "after a per-view least-squares scale + shift to GT; mean over views of the per-view value", depth, "-"),
        ("Normal prior", "angle to the GT normal, pooled over all pixels of all views", normal, "-"),
        ("Photometric content", "luminance gradient inside surfaces (boundary band and image border excluded)", photo, NO_ANCHOR),
        ("Capture", f"surface points from {_get(sheet, 'capture.points_source')}", capture, NO_ANCHOR),
        ("Thin parts", "width along the medial axis, all views pooled",
         [("width, median", "thin_parts.median_px", _px), ("width, 90th pct", "thin_parts.p90_px", _px)], NO_ANCHOR),
    ]


def render_card(sheet: dict[str, Any], plot_name: str | None = None) -> str:
    """The markdown card of a datasheet dict, with a link to its plot ``plot_name`` when given."""
    info = sheet["scene"]
    used, anchors, caveats = anchors_for(info.get("prior_profile"), str(info.get("format")))
    notes: dict[str, int] = {}
    lines = [f"# Datasheet: {info['name']}", "",
             f"{info['format']} format, {info['kind']} scene, {info['views']} views of {info['width']} x {info['height']} px; "
             f"prior profile: {info.get('prior_profile') or 'none recorded'}; anchors: {used or 'none'}.",
             "Definitions of every field: docs/datasheet.md."]
    lines += [f"Note: {c}." for c in caveats]
    for title, scope, rows, unanchored in _sections(sheet):
        lines += ["", f"## {title}", "", f"{scope}.", "", "| property | this scene | real-data anchor | source |", "|---|---|---|---|"]
        for label, key, fmt in rows:
            value = _get(sheet, key)
            shown = "n/a" if value is None else fmt(value)
            anchor = anchors.get(key)
            if anchor is not None:
                k = notes.setdefault(anchor.note, len(notes) + 1)
                lines.append(f"| {label} | {shown} | {_anchor_text(anchor, fmt)} | {anchor.cite} [{k}] |")
            else:
                lines.append(f"| {label} | {shown} | - | {unanchored} |")
    outcomes = [(k, a) for k, a in anchors.items() if k.startswith("reference.")]
    if outcomes:
        lines += ["", "## Reference outcomes on the real dataset", "",
                  "Reconstruction results the real data gives; measured by `bench run`, not by the datasheet.", "",
                  "| property | this scene | real-data anchor | source |", "|---|---|---|---|"]
        for key, anchor in outcomes:
            k = notes.setdefault(anchor.note, len(notes) + 1)
            label = {"reference.no_prior_fscore": "F-score, no prior (UNISURF)", "reference.monosdf_fscore": "F-score, MonoSDF"}[key]
            lines.append(f"| {label} | not measured here | {anchor.low:.3f} | {anchor.cite} [{k}] |")
    if plot_name:
        lines += ["", f"![normal-prior error CDF and views per point]({plot_name})"]
    lines += ["", "Sources:", ""]
    lines += [f"[{k}] {note}." for note, k in notes.items()]
    return "\n".join(lines) + "\n"


# The summary's columns: (header, datasheet key, formatter); the anchor row takes each key's anchor.
SUMMARY_COLUMNS: Rows = [
    ("depth AbsRel", "depth_prior.all.abs_rel", _pct),
    ("depth delta1", "depth_prior.all.delta1", _pct),
    ("normal mean", "normal_prior.all.mean_deg", _deg),
    ("normal median", "normal_prior.all.median_deg", _deg),
    ("normal < 11.25 deg", "normal_prior.all.within_11_25", _pct),
    ("normal mean planar / thin / silhouette", "", _deg),
    ("textureless wall + ceiling", "photometric.textureless_fraction_wall_ceiling", _pct),
    ("views per point (median)", "capture.views_per_point.median", _num),
    ("baseline / depth", "capture.baseline_depth_ratio.median_of_median", _num),
]


def _summary_cell(sheet: dict[str, Any], key: str, fmt: Fmt) -> str:
    if not key:  # the normal prior's error by region: where the real errors lie
        parts = [_get(sheet, f"normal_prior.{r}.mean_deg") for r in ("planar_background", "thin", "silhouette")]
        return " / ".join("n/a" if v is None else f"{v:.0f}" for v in parts) + " deg"
    value = _get(sheet, key)
    return "n/a" if value is None else fmt(value)


def render_summary(sheets: dict[str, dict[str, Any]]) -> str:
    """One markdown table of several scenes' datasheets (a row each, the headline fields), then a row per
    prior profile / dataset of the real-data anchors of those fields, with their sources."""
    header = ["scene", "prior profile"] + [h for h, _, _ in SUMMARY_COLUMNS]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    anchor_rows: dict[tuple[str | None, str], dict[str, Anchor]] = {}
    for name, sheet in sheets.items():
        info = sheet["scene"]
        used, anchors, _ = anchors_for(info.get("prior_profile"), str(info.get("format")))
        anchor_rows.setdefault((used, str(info.get("format"))), anchors)
        cells = [name, str(info.get("prior_profile") or "-")] + [_summary_cell(sheet, k, f) for _, k, f in SUMMARY_COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    notes: dict[str, int] = {}
    for (profile, dataset), anchors in anchor_rows.items():
        cells = [f"real ({dataset}, anchors of {profile})", "-"]
        for _, key, fmt in SUMMARY_COLUMNS:
            a = anchors.get(key) if key else None
            if a is None:
                cells.append("-")
                continue
            k = notes.setdefault(a.note, len(notes) + 1)
            cells.append(f"{_anchor_text(a, fmt)} [{k}]")
        lines.append("| " + " | ".join(cells) + " |")
    lines += [""] + [f"[{k}] {note}." for note, k in notes.items()]
    return "\n".join(lines) + "\n"


def datasheet_figure(sheet: dict[str, Any]) -> bytes:
    """PNG: left, the CDF of the normal-prior angular error per region (the ScanNet anchor's shares at
    11.25 / 22.5 / 30 deg as markers); right, the histogram of views per sampled surface point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    fig, (left, right) = plt.subplots(1, 2, figsize=(9.0, 3.4))
    normal = sheet.get("normal_prior") or {}
    for region in ("all",) + REGION_NAMES:
        cdf = (normal.get(region) or {}).get("cdf")
        if cdf:
            left.plot([k * CDF_STEP_DEG for k in range(len(cdf))], cdf, label=region, lw=2 if region == "all" else 1)
    _, anchors, _ = anchors_for(sheet["scene"].get("prior_profile"), str(sheet["scene"].get("format")))
    for t in NORMAL_THRESHOLDS_DEG:
        a = anchors.get(f"normal_prior.all.{within_key(t)}")
        if a is not None:
            left.errorbar([t], [(a.low + a.high) / 2], yerr=[[(a.high - a.low) / 2], [(a.high - a.low) / 2]], fmt="k*", ms=8)
    left.set(xlabel="normal-prior angular error (deg)", ylabel="share of pixels with error <= x", xlim=(0, 90), ylim=(0, 1.01),
             title="normal prior (stars: real-data anchor)" if anchors else "normal prior")
    if not normal:
        left.text(45, 0.5, "no normal prior", ha="center")
    else:
        left.legend(fontsize=7, loc="lower right")
    hist = (sheet.get("capture") or {}).get("views_histogram") or []
    hist = hist[: max((k for k, c in enumerate(hist) if c), default=0) + 1]  # up to the largest count of views seen
    right.bar(range(len(hist)), hist, width=0.9, color="0.4")
    right.xaxis.set_major_locator(MaxNLocator(integer=True))
    right.set(xlabel="views seeing the point", ylabel="sampled surface points",
              title=f"capture ({(sheet.get('capture') or {}).get('points_source')})")
    fig.suptitle(f"{sheet['scene']['name']}", fontsize=9)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=80)
    plt.close(fig)
    return buf.getvalue()


def write_card(sheet: dict[str, Any], card_path: Path) -> list[Path]:
    """Write the card to ``card_path`` and its plot beside it (``<stem>.png``, linked from the card), each
    atomically. Returns the written paths."""
    card_path = Path(card_path)
    png = card_path.with_suffix(".png")
    text = render_card(sheet, plot_name=png.name)
    atomic_write_bytes(png, datasheet_figure(sheet))
    atomic_write_text(card_path, text)
    return [card_path, png]
