"""The harness version (``bench.__version__``): part of every cached dataset's key and of every job id, so that
datasets and rows of an earlier version are not reused (CHANGELOG.md). It lives in the data layer, the lowest
layer that needs it, so that ``bench.data`` imports nothing of the rest of the harness."""

__version__ = "0.2.0"
