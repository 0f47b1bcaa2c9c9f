"""The trust-region controls of PETSc's KSPSTCG, which petsc4py does not wrap.

``KSPCGSetRadius``, ``KSPCGGetNormD`` and ``KSPCGGetObjFcn`` exist under these names in
PETSc 3.18 and 3.22 (Debian 12 and 13) but not in their petsc4py: they are called through
ctypes in the PETSc library petsc4py links, with the KSP's handle. The radius bounds the
Euclidean norm ||d||_2 of the direction in both versions (measured by
tests/test_ksp_trust_region.py; later releases add ``KSPCGSetTRNormType`` to choose the
preconditioner's norm instead, which these lack).
"""

from __future__ import annotations

import ctypes
import functools

from petsc4py import PETSc

__all__ = ["set_radius", "direction_norm", "model_value"]


@functools.lru_cache(maxsize=1)
def _library() -> ctypes.CDLL:
    """petsc4py's extension module, whose symbol look-up (``dlsym``) also searches the
    libraries it links, PETSc's among them: the PETSc petsc4py uses, whatever its path."""
    library = ctypes.CDLL(PETSc.__file__)
    library.KSPCGSetRadius.argtypes = [ctypes.c_void_p, ctypes.c_double]
    for name in ("KSPCGGetNormD", "KSPCGGetObjFcn"):
        getattr(library, name).argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_double)]
    return library


def _check(code: int) -> None:
    if code != 0:
        raise PETSc.Error(code)


def set_radius(ksp: PETSc.KSP, radius: float) -> None:
    """The trust-region radius of a KSPSTCG (logically collective: the same on all ranks)."""
    _check(_library().KSPCGSetRadius(ctypes.c_void_p(ksp.handle), float(radius)))


def _get(name: str, ksp: PETSc.KSP) -> float:
    value = ctypes.c_double()
    _check(getattr(_library(), name)(ctypes.c_void_p(ksp.handle), ctypes.byref(value)))
    return value.value


def direction_norm(ksp: PETSc.KSP) -> float:
    """||d||_2 of the last solve's direction d."""
    return _get("KSPCGGetNormD", ksp)


def model_value(ksp: PETSc.KSP) -> float:
    """The last solve's quadratic model at its direction: 1/2 d^T A d - b^T d."""
    return _get("KSPCGGetObjFcn", ksp)
