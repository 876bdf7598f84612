"""hgrender: partially-coherent light rendering in Hermite-Gauss space (the command line)."""

from hgcore import __version__

__all__ = ["__version__"]
