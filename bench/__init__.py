"""The benchmark harness: scene synthesis, on-disk formats and loaders, method registry, job runner,
tables and reports. Data flows one way: recipe -> dataset folder -> Scene -> method -> metrics -> row
-> table (see docs/architecture.md)."""

from bench.data.version import __version__

__all__ = ["__version__"]
