"""Complex numbers as a (real, imaginary) pair of arrays of either array library.

Dr.Jit kernels in the integrator have no complex dtype that mixes freely with ``Float``, and the optics
formulas must run unchanged on NumPy (reference, tests) and Dr.Jit (Mitsuba kernels). ``ComplexPair`` keeps
the two parts as separate real arrays and implements the few operations the interaction formulas need with
ordinary element-wise arithmetic; the transcendental ones take the ``ArrayOps`` namespace explicitly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hgcore.optics.array_ops import ArrayOps


@dataclass(frozen=True)
class ComplexPair:
    """z = re + i·im with ``re`` and ``im`` real arrays (or Python floats) of one library."""

    re: Any
    im: Any

    @staticmethod
    def real(value: Any) -> ComplexPair:
        """A real number as a complex pair (imaginary part 0 of the same shape)."""
        return ComplexPair(value, value * 0.0)

    @staticmethod
    def lift(value: Any) -> ComplexPair:
        """``value`` itself when it is a ``ComplexPair``, else the real number ``value``."""
        return value if isinstance(value, ComplexPair) else ComplexPair.real(value)

    def __add__(self, other: Any) -> ComplexPair:
        if isinstance(other, ComplexPair):
            return ComplexPair(self.re + other.re, self.im + other.im)
        return ComplexPair(self.re + other, self.im)

    __radd__ = __add__

    def __sub__(self, other: Any) -> ComplexPair:
        if isinstance(other, ComplexPair):
            return ComplexPair(self.re - other.re, self.im - other.im)
        return ComplexPair(self.re - other, self.im)

    def __rsub__(self, other: Any) -> ComplexPair:
        return ComplexPair(other - self.re, -self.im)

    def __neg__(self) -> ComplexPair:
        return ComplexPair(-self.re, -self.im)

    def __mul__(self, other: Any) -> ComplexPair:
        if isinstance(other, ComplexPair):
            return ComplexPair(
                self.re * other.re - self.im * other.im, self.re * other.im + self.im * other.re
            )
        return ComplexPair(self.re * other, self.im * other)

    __rmul__ = __mul__

    def __truediv__(self, other: Any) -> ComplexPair:
        if isinstance(other, ComplexPair):
            # z/w = z·w*/|w|²: one real division per part.
            inverse_norm = 1.0 / other.abs2()
            return ComplexPair(
                (self.re * other.re + self.im * other.im) * inverse_norm,
                (self.im * other.re - self.re * other.im) * inverse_norm,
            )
        return ComplexPair(self.re / other, self.im / other)

    def __rtruediv__(self, other: Any) -> ComplexPair:
        return ComplexPair.lift(other) / self

    def conj(self) -> ComplexPair:
        """Complex conjugate z*."""
        return ComplexPair(self.re, -self.im)

    def abs2(self) -> Any:
        """Squared modulus |z|² (real array)."""
        return self.re * self.re + self.im * self.im

    def sqrt(self, ops: ArrayOps) -> ComplexPair:
        """Principal square root (Re ≥ 0; Im has the sign of Im z, +0 on the negative real axis).

        √z = √((|z|+x)/2) + i·sign(y)·√((|z|−x)/2); the ``maximum(…, 0)`` guards rounding below zero.
        On the negative real axis (y = 0, x < 0) this gives +i√|x|, the branch an evanescent wave
        e^{i k q z} needs to decay.
        """
        modulus = ops.sqrt(self.abs2())
        root_re = ops.sqrt(ops.maximum(0.5 * (modulus + self.re), 0.0))
        root_im_abs = ops.sqrt(ops.maximum(0.5 * (modulus - self.re), 0.0))
        return ComplexPair(root_re, ops.where(self.im < 0.0, -root_im_abs, root_im_abs))

    @staticmethod
    def exp_i(phase: Any, ops: ArrayOps) -> ComplexPair:
        """e^{i·phase}; a complex ``phase`` a + ib gives e^{−b}(cos a + i sin a)."""
        if isinstance(phase, ComplexPair):
            magnitude = ops.exp(-phase.im)
            return ComplexPair(magnitude * ops.cos(phase.re), magnitude * ops.sin(phase.re))
        return ComplexPair(ops.cos(phase), ops.sin(phase))
