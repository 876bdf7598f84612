"""hgrender: partially-coherent light rendering in Hermite-Gauss space."""

__version__ = "0.1.0"
