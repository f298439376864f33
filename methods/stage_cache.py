"""Checkpoints of a training stage that several jobs share exactly, trained once and reused.

Table 4's four MonoInstance rows run the same stage 1 (plain MonoSDF for the first quarter of the schedule: the
modules switch on only after it); a measured ablation run had all 24 trained jobs identical at 25 % to the 6
digits the CSV holds, row by row. A method that knows such a stage keys its end state by everything that decides
it (:func:`stage_key`: config, data, seed, thread count, matrix-product path, code), stores it here, and a later job
with the same key loads it instead of training it again. Results do not change: the loaded state is the one the
job would have computed, and a test compares a resumed job with one that trained every step
(``tests/methods/test_stage_cache.py``).

The folder comes from the harness (``bench.execute.run_job``: ``<dataset cache>/_stages``, with the matrix-product
path as ``environment``) through :func:`stage_checkpoints`; outside it (a direct ``fit``) :func:`checkpoint_dir` is None and nothing is shared.
Writes are atomic, so two jobs finishing the same stage at once both write the same bytes, and a reader never sees a
half-written file.
"""

from __future__ import annotations

import contextlib
import contextvars
import hashlib
import io
import json
import warnings
from pathlib import Path
from typing import Any, Iterator

import torch

from bench.data.atomic import atomic_write_bytes

_DIR: contextvars.ContextVar[Path | None] = contextvars.ContextVar("stage_checkpoint_dir", default=None)
_ENV: contextvars.ContextVar[dict[str, str]] = contextvars.ContextVar("stage_checkpoint_env", default={})

CODE_DIRS = ("monosdf",)
"""Folders of ``methods/`` whose source files enter every key: a code change invalidates the stored stages."""


@contextlib.contextmanager
def stage_checkpoints(folder: Path | None, environment: dict[str, str] | None = None) -> Iterator[None]:
    """Let the methods called inside share stage checkpoints in ``folder`` (None: no sharing). ``environment``:
    what the harness knows of this process that changes float rounding and that methods cannot see (the
    matrix-product path, ``bench.mkl_dispatch.blas_path``); it enters every key."""
    token = _DIR.set(None if folder is None else Path(folder))
    env_token = _ENV.set(dict(environment or {}))
    try:
        yield
    finally:
        _DIR.reset(token)
        _ENV.reset(env_token)


def checkpoint_dir() -> Path | None:
    """The folder set by :func:`stage_checkpoints`, or None."""
    return _DIR.get()


def code_hash() -> str:
    """SHA-256 of the source files (``*.py``, ``*.cpp``) of :data:`CODE_DIRS` and of this module, names and bytes."""
    h = hashlib.sha256()
    root = Path(__file__).parent
    files = [Path(__file__)] + [p for d in CODE_DIRS for p in sorted((root / d).iterdir()) if p.suffix in (".py", ".cpp")]
    for p in files:
        h.update(p.name.encode())
        h.update(p.read_bytes())
    return h.hexdigest()


def tensor_digest(*tensors: torch.Tensor | None) -> str:
    """SHA-256 of tensors' dtypes, shapes and bytes (None counts as a marker): a job's training data."""
    h = hashlib.sha256()
    for t in tensors:
        if t is None:
            h.update(b"none")
            continue
        c = t.detach().contiguous().cpu()
        h.update(f"{c.dtype}{tuple(c.shape)}".encode())
        h.update(c.numpy().tobytes())
    return h.hexdigest()


def stage_key(parts: dict[str, Any]) -> str:
    """Key of a stage's end state: SHA-256 of ``parts`` (JSON, sorted keys; values JSON-representable), the
    harness's ``environment`` (:func:`stage_checkpoints`), the code hash and the torch version. 24 hex digits."""
    blob = json.dumps({"parts": parts, "environment": _ENV.get(), "code": code_hash(), "torch": torch.__version__},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def _path(key: str) -> Path | None:
    folder = checkpoint_dir()
    return None if folder is None else folder / f"{key}.pt"


def load_stage(key: str) -> dict[str, Any] | None:
    """The stored state for ``key``, or None (no folder, nothing stored, or a file torch cannot read: the job then
    trains the stage itself and stores it anew, with a warning naming the file)."""
    path = _path(key)
    if path is None or not path.is_file():
        return None
    try:
        return torch.load(path, weights_only=False)
    except Exception as exc:  # a damaged file (writes are atomic, but a disk can fail): train instead of failing the job
        warnings.warn(f"{path}: unreadable stage checkpoint ({type(exc).__name__}: {exc}); training the stage instead")
        return None


def save_stage(key: str, state: dict[str, Any]) -> None:
    """Store ``state`` for ``key`` (atomic; no-op without a folder)."""
    path = _path(key)
    if path is None:
        return
    buf = io.BytesIO()
    torch.save(state, buf)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buf.getvalue())
