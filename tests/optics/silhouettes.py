"""What a far receiver sees of an open cylinder, sampled by ray casting (independent of the closed forms
of ``hgcore.optics.sources``), and the tolerance Monte Carlo comparisons use."""

from __future__ import annotations

import numpy as np

from hgcore.optics.frames import transverse_frame

MC_SIGMAS = 5.0  # tolerance = 5 Monte Carlo standard errors: a false failure has probability ~6e-7


def unit(vector: tuple[float, float, float]) -> np.ndarray:
    array = np.asarray(vector, dtype=float)
    return array / np.linalg.norm(array)


def silhouette_samples(
    radius_m: float, length_m: float, axis: np.ndarray, direction: np.ndarray, count: int, seed: int
) -> np.ndarray:
    """Transverse points (x, y) uniformly covering the part of an open cylinder's outer lateral surface that
    a far receiver along ``direction`` sees, by ray casting (independent of the closed form).

    The receiver looks back along −d: on the line p + t·d the first surface it meets is the larger root t₊
    of the infinite cylinder |q − (q·a)a| = R, where the outer side faces it; the point radiates when that
    hit lies within the length, |(p + t₊d)·a| ≤ L/2. Otherwise the line enters through an open end (the
    unlit inside) or misses.
    """
    x_axis, y_axis = transverse_frame(direction)
    half_extent = 0.5 * length_m + radius_m
    rng = np.random.default_rng(seed)
    planar = rng.uniform(-half_extent, half_extent, size=(count, 2))
    points = planar[:, :1] * x_axis + planar[:, 1:] * y_axis
    d_radial = direction - np.dot(direction, axis) * axis
    p_radial = points - np.outer(points @ axis, axis)
    a = float(d_radial @ d_radial)
    b = p_radial @ d_radial
    c = np.einsum("ij,ij->i", p_radial, p_radial) - radius_m**2
    discriminant = b * b - a * c
    t_near = (-b + np.sqrt(np.maximum(discriminant, 0.0))) / a
    along = points @ axis + t_near * float(direction @ axis)
    hit = (discriminant >= 0.0) & (np.abs(along) <= 0.5 * length_m)
    return planar[hit]
