"""Deterministic ``.npz`` writing and checked ``.npz`` / ``.npy`` reading.

``np.savez`` stamps every zip entry with the current time, so writing the same arrays twice gives
different bytes. :func:`save_npz` writes the same container (a stored, uncompressed zip of ``.npy``
members, readable by ``np.load``) with a fixed entry date (1980-01-01 00:00:00, the earliest zip date)
and fixed permissions, so equal arrays give byte-identical files.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path
from typing import Mapping

import numpy as np

from bench.data.errors import BenchInputError

_FIXED_DATE = (1980, 1, 1, 0, 0, 0)


def save_npz(path: Path, arrays: Mapping[str, np.ndarray]) -> None:
    """Write ``arrays`` (name -> array) to ``path`` as a deterministic ``.npz`` (members in the given order)."""
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED) as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asarray(arr), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=_FIXED_DATE)
            info.compress_type = zipfile.ZIP_STORED
            info.create_system = 3  # unix, whatever the host
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())


def save_npy(path: Path, arr: np.ndarray) -> None:
    """Write one array as ``.npy`` (the format has no timestamp, so it is deterministic)."""
    with open(path, "wb") as f:
        np.lib.format.write_array(f, np.asarray(arr), allow_pickle=False)


def load_npz(path: Path) -> dict[str, np.ndarray]:
    """Read every member of an ``.npz``; BenchInputError if missing or unreadable."""
    if not path.is_file():
        raise BenchInputError(path, "file is missing")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: np.asarray(data[k]) for k in data.files}
    except Exception as e:  # zipfile.BadZipFile, ValueError, OSError ...
        raise BenchInputError(path, f"not a readable .npz file ({type(e).__name__}: {e})") from None


def load_npy(path: Path) -> np.ndarray:
    """Read one ``.npy`` array (no pickles); BenchInputError if missing or unreadable."""
    if not path.is_file():
        raise BenchInputError(path, "file is missing")
    try:
        return np.load(path, allow_pickle=False)
    except Exception as e:
        raise BenchInputError(path, f"not a readable .npy file ({type(e).__name__}: {e})") from None
