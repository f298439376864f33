"""Writing the same Scene twice gives byte-identical folders."""

from __future__ import annotations

import time
import zipfile

import pytest
from fmt_helpers import FORMATS, write


def snapshot(root):
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("fmt", FORMATS)
def test_double_write_is_byte_identical(tmp_path, scene, gt_mesh, fmt):
    kw = {"factors": (2,)} if fmt == "llff" else {}
    a = snapshot(write(scene, tmp_path / "a", fmt, gt_mesh=gt_mesh, **kw))
    if fmt == "scannet":
        time.sleep(2.1)  # zip timestamps have a 2 s resolution: make a clock-dependent write differ
    b = snapshot(write(scene, tmp_path / "b", fmt, gt_mesh=gt_mesh, **kw))
    assert a.keys() == b.keys()
    for name in a:
        assert a[name] == b[name], name


def test_npz_has_fixed_dates(tmp_path, scene):
    root = write(scene, tmp_path / "s", "scannet")
    with zipfile.ZipFile(root / "cameras.npz") as zf:
        assert {i.date_time for i in zf.infolist()} == {(1980, 1, 1, 0, 0, 0)}
        assert zf.namelist()[:2] == ["world_mat_0.npy", "scale_mat_0.npy"]
