"""Loading Mitsuba 3 with a working Dr.Jit backend and choosing the spectral variant.

Dr.Jit's LLVM backend needs a recent libLLVM (Debian's ``libllvm19``; LLVM 14/15 crash), so the path is
set through ``DRJIT_LIBLLVM_PATH`` before Mitsuba is imported. The variant is ``cuda_ad_spectral`` where
an NVIDIA GPU is usable, else ``llvm_ad_spectral``; the setting ``variant`` (``HGRENDER_VARIANT``) or an
explicit argument wins. The setting ``render_threads`` (``HGRENDER_RENDER_THREADS``) sizes Dr.Jit's CPU
thread pool. Both are read from the process's ``hgcore.settings.Settings``.
"""

from __future__ import annotations

import glob
import os
from types import ModuleType

from hgcore.errors import InputError
from hgcore.settings import Settings

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


def load_mitsuba(variant: str | None = None) -> ModuleType:
    """Import Mitsuba, select a spectral variant and return the ``mitsuba`` module.

    ``variant`` (default: the setting ``variant``) may be ``auto`` or one of ``SUPPORTED_VARIANTS``.
    """
    point_drjit_at_libllvm()
    import mitsuba as mi

    settings = Settings()
    threads = settings.render_threads
    if threads:
        # Workers started side by side share the cores (`hgrender serve` sets cores // workers).
        import drjit as dr

        dr.set_thread_count(int(threads))
    requested = variant or settings.variant
    if requested == "auto":
        requested = "cuda_ad_spectral" if _cuda_available(mi) else "llvm_ad_spectral"
    if requested not in SUPPORTED_VARIANTS:
        raise InputError(f"variant: {requested!r} is not one of {', '.join(SUPPORTED_VARIANTS)} or 'auto'")
    if mi.variant() != requested:
        mi.set_variant(requested)
    return mi
