"""libpetsc's functions that petsc4py 3.18 does not wrap, called through ctypes.

The library is reached through the petsc4py extension module, which links it.
"""

from __future__ import annotations

import ctypes

import numpy as np
from petsc4py import PETSc

_library = None


def petsc_library():
    """libpetsc, with the argument types of the functions primordia calls set."""
    global _library
    if _library is None:
        _library = ctypes.CDLL(PETSc.__file__)
        _library.PetscOptionsUsed.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.POINTER(ctypes.c_int)]
        _library.MatUpdateMPIAIJWithArray.argtypes = [ctypes.c_void_p, ctypes.c_void_p]
        _library.MatUpdateMPIAIJWithArray.restype = ctypes.c_int
        _library.MatInitializePackage.restype = ctypes.c_int
        _library.PetscFunctionListFind_Private.argtypes = [ctypes.c_void_p, ctypes.c_char_p,
                                                           ctypes.POINTER(ctypes.c_void_p)]
        _library.PetscFunctionListFind_Private.restype = ctypes.c_int
    return _library


def matrix_ordering_registered(name: str) -> bool:
    """Whether PETSc has the matrix ordering ``name`` (``pc_factor_mat_ordering_type``), looked up in its
    ``MatOrderingList`` without running it: some registered orderings abort the process on this PETSc."""
    library = petsc_library()
    if library.MatInitializePackage():  # registers the orderings (once)
        return False
    found = ctypes.c_void_p()
    listed = ctypes.c_void_p.in_dll(library, "MatOrderingList")
    if library.PetscFunctionListFind_Private(listed, name.encode(), ctypes.byref(found)):
        return False
    return bool(found.value)


def update_mpiaij_values(matrix, values: np.ndarray) -> None:
    """New values, in the order of the local CSR rows the matrix was made from, into a parallel AIJ matrix made by
    ``createAIJWithArrays`` with sorted columns (``MatUpdateMPIAIJWithArray``: a copy of each row's segments
    into PETSc's diagonal and off-diagonal blocks, where ``setValuesCSR`` looks up every entry).  Collective."""
    if values.dtype != PETSc.ScalarType or not values.flags.c_contiguous:
        raise ValueError("update_mpiaij_values: values must be a contiguous array of PETSc scalars")
    error = petsc_library().MatUpdateMPIAIJWithArray(matrix.handle, values.ctypes.data)
    if error:
        raise PETSc.Error(error)
