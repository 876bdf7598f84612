"""Shared core of hgrender: optics, colour, the artifact format, settings and the job domain.

Layering (enforced by import-linter in ``make lint``, see ``docs/architecture.md``):
``hgcore`` ← ``schemas`` ← {``worker``, ``service``} ← ``hgrender`` (CLI). Nothing here imports a package
above it, Mitsuba or Dr.Jit: the optics run on NumPy here and on Dr.Jit through ``worker.render.drjit_ops``.
"""

__version__ = "0.1.0"
"""The release of the whole project (API, workers, CLI and artifact format share it)."""
