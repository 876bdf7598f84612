"""Shared core of hgrender: optics, colour, the artifact format, settings and the job domain.

Layering (enforced by import-linter in ``make lint``, see ``docs/architecture.md``):
``hgcore`` ← ``schemas`` ← {``worker``, ``service``} ← ``hgrender`` (CLI). Nothing here imports a package
above it, Mitsuba or Dr.Jit at module level (Dr.Jit kernels import it lazily, inside ``drjit_ops``).
"""
