"""The data layer: what a method and a metric may know about a dataset, and nothing else of the harness.

Modules: :mod:`~bench.data.scene` (the ``Scene`` contract every loader returns and every method reads),
:mod:`~bench.data.formats` (the four on-disk formats: writers, loaders, detection),
:mod:`~bench.data.synth` (procedural scenes and the effects simulated on their priors),
:mod:`~bench.data.datasets` (recipe -> cached dataset folder -> ``Scene``),
:mod:`~bench.data.errors` (``BenchInputError``: one message naming the file and the problem),
:mod:`~bench.data.atomic` (atomic file writes).

Layering (``tests/test_architecture.py``): this package imports nothing of the rest of ``bench`` and
nothing of ``methods``; ``methods`` import only this package from ``bench``; ``metrics`` imports
neither. Camera conventions (OpenCV axes, pixel centres at integer coordinates, z-depth in metres) are
``metrics.camera``'s, shared by every layer.
"""
