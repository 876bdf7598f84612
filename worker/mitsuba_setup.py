"""Configuring Mitsuba 3 for a process: a working Dr.Jit backend, the spectral variant, the thread count.

A process's entry point configures Mitsuba once, from its own ``hgcore.settings.Settings``, before it
imports the renderer: the queue worker (``worker.preload``), ``hgrender render`` and ``regress``, the
gallery, the benchmarks and the test session (``tests/conftest.py``) call ``configure_mitsuba(variant,
render_threads)``. The renderer's modules subclass variant-specific Mitsuba classes, so they bind the
configured module when imported (``configured_mitsuba``), which changes nothing and fails clearly in a
process that configured none: importing a module never selects a variant, starts a thread pool or
writes the environment (the one exception is ``point_drjit_at_libllvm``, called by ``configure_mitsuba``).

Dr.Jit's LLVM backend needs a recent libLLVM (Debian's ``libllvm19``; LLVM 14/15 crash), so the path is
set through ``DRJIT_LIBLLVM_PATH`` before Mitsuba is first used. The variant is ``cuda_ad_spectral`` where
an NVIDIA GPU is usable, else ``llvm_ad_spectral``; the setting ``variant`` (``HGRENDER_VARIANT``) names
another. The setting ``render_threads`` (``HGRENDER_RENDER_THREADS``) sizes Dr.Jit's CPU thread pool.
"""

from __future__ import annotations

import glob
import os
import sys
from types import ModuleType

from hgcore.errors import InputError

SUPPORTED_VARIANTS = ("llvm_ad_spectral", "cuda_ad_spectral")
_LIBLLVM_PATTERNS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.19*",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.19*",
    "/usr/lib/llvm-19/lib/libLLVM.so*",
    "/usr/lib/x86_64-linux-gnu/libLLVM-19.so",
    "/usr/lib/aarch64-linux-gnu/libLLVM-19.so",
)


def find_libllvm() -> str | None:
    """Path of a libLLVM 19 shared library, or None."""
    for pattern in _LIBLLVM_PATTERNS:
        matches = sorted(glob.glob(pattern))
        if matches:
            return matches[0]
    return None


def point_drjit_at_libllvm() -> None:
    """Set ``DRJIT_LIBLLVM_PATH`` to libLLVM 19 unless the environment names one; Dr.Jit reads it when it is
    first imported, so this runs before any ``import drjit`` or ``import mitsuba``."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        libllvm = find_libllvm()
        if libllvm is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = libllvm


def _cuda_available(mitsuba: ModuleType) -> bool:
    if "cuda_ad_spectral" not in mitsuba.variants():
        return False
    try:
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # any failure to initialise CUDA means "no GPU"
        return False


def configure_mitsuba(variant: str = "auto", render_threads: int | None = None) -> ModuleType:
    """Import Mitsuba, select the spectral ``variant`` (``auto`` or one of ``SUPPORTED_VARIANTS``) and size
    Dr.Jit's CPU thread pool (None: all cores); return the ``mitsuba`` module. Called by a process's
    entry point, from its settings (``settings.variant``, ``settings.render_threads``)."""
    point_drjit_at_libllvm()
    import mitsuba as mi

    if render_threads:
        # Workers started side by side share the cores (`hgrender serve` sets cores // workers).
        import drjit as dr

        dr.set_thread_count(int(render_threads))
    requested = variant
    if requested == "auto":
        requested = "cuda_ad_spectral" if _cuda_available(mi) else "llvm_ad_spectral"
    if requested not in SUPPORTED_VARIANTS:
        raise InputError(f"variant: {requested!r} is not one of {', '.join(SUPPORTED_VARIANTS)} or 'auto'")
    if mi.variant() != requested:
        mi.set_variant(requested)
    return mi


def configured_mitsuba() -> ModuleType:
    """The ``mitsuba`` module with the variant this process configured (``configure_mitsuba``); changes
    nothing. The renderer's modules bind it when imported: Python integrators subclass variant-specific
    classes."""
    mi = sys.modules.get("mitsuba")
    if mi is None or mi.variant() not in SUPPORTED_VARIANTS:
        raise RuntimeError(
            "Mitsuba is not configured in this process: call worker.mitsuba_setup.configure_mitsuba("
            "settings.variant, settings.render_threads) before importing the renderer"
        )
    return mi
