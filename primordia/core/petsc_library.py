"""libpetsc's functions that petsc4py 3.18 does not wrap, called through ctypes.

The library is reached through the petsc4py extension module, which links it.
"""

from __future__ import annotations

import ctypes
from contextlib import contextmanager

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
        _library.MatMPIAIJGetSeqAIJ.argtypes = [ctypes.c_void_p, *[ctypes.POINTER(ctypes.c_void_p)] * 3]
        for name in ("MatSeqAIJGetArray", "MatSeqAIJRestoreArray"):
            getattr(_library, name).argtypes = [ctypes.c_void_p, ctypes.POINTER(ctypes.c_void_p)]
        for name in ("MatMPIAIJGetSeqAIJ", "MatSeqAIJGetArray", "MatSeqAIJRestoreArray"):
            getattr(_library, name).restype = ctypes.c_int
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


class BlockPlaces:
    """Where each value of a parallel AIJ matrix, in the order of the local CSR rows it was made from
    (``createAIJWithArrays``, sorted columns), lies in PETSc's diagonal and off-diagonal blocks.

    Each block keeps the rows' order with the other block's entries left out, so an entry's place is its count
    among the entries of its block before it (:attr:`place`; :attr:`split` past that in the off-diagonal block).
    Code that computes the values one by one writes them there itself (:meth:`blocks`), with no copy: the cell
    density's fitted operator, 0.11 ms a step of example 1a at 171^2 on 2 ranks against a copy by runs, 0.12 ms
    with ``MatUpdateMPIAIJWithArray`` (session of 2026-12-05).  Made by :meth:`of`, which checks the order on
    the matrix itself.
    """

    def __init__(self, matrix, in_diagonal: np.ndarray):
        library = petsc_library()
        diagonal, off_diagonal, columns_map = ctypes.c_void_p(), ctypes.c_void_p(), ctypes.c_void_p()
        error = library.MatMPIAIJGetSeqAIJ(matrix.handle, ctypes.byref(diagonal), ctypes.byref(off_diagonal),
                                           ctypes.byref(columns_map))
        if error:
            raise PETSc.Error(error)
        self._matrix = matrix  # the blocks live as long as the matrix
        self._in_diagonal = in_diagonal
        self._handles = (diagonal, off_diagonal)
        #: the diagonal block's number of local entries
        self.split = int(np.count_nonzero(in_diagonal))
        #: each local entry's place, in the rows' order: its position in the diagonal block's values, or
        #: ``split`` past its position in the off-diagonal block's
        self.place = np.empty(len(in_diagonal), dtype=np.int64)
        self.place[in_diagonal] = np.arange(self.split)
        self.place[~in_diagonal] = self.split + np.arange(len(in_diagonal) - self.split)

    @classmethod
    def of(cls, matrix, columns: np.ndarray) -> "BlockPlaces | None":
        """The places of ``matrix``'s values (``columns``: the global column of each local entry, sorted in each
        row), or None on every rank if on any rank the matrix does not read back, by rows, what was written at
        them (collective).  Leaves every value zero.

        The values are written into PETSc's own arrays: a block holding fewer entries than ``columns`` puts in it
        would be written past its end before anything could be read back, so the blocks' sizes are compared
        with ``columns`` first, and a matrix whose sizes differ on any rank is not written at all."""
        start, end = matrix.getOwnershipRangeColumn()
        in_diagonal = (columns >= start) & (columns < end)
        diagonal_entries = matrix.getDiagonalBlock().getInfo()["nz_used"]
        local_entries = matrix.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"]
        fits = diagonal_entries == np.count_nonzero(in_diagonal) and local_entries == len(columns)
        if not all(matrix.getComm().tompi4py().allgather(fits)):
            return None
        places = cls(matrix, in_diagonal)
        numbered = np.arange(1.0, len(columns) + 1.0, dtype=PETSc.ScalarType)
        places.write(numbered)
        matrix.assemble()
        ordered = bool(np.array_equal(matrix.getValuesCSR()[2], numbered))
        places.write(np.zeros(len(columns), dtype=PETSc.ScalarType))
        matrix.assemble()
        return places if all(matrix.getComm().tompi4py().allgather(ordered)) else None

    def write(self, values: np.ndarray) -> None:
        """``values`` (contiguous PETSc scalars, in the rows' order) into the blocks, at :attr:`place`; assembling
        the matrix then marks it changed."""
        if values.dtype != PETSc.ScalarType or not values.flags.c_contiguous or len(values) != len(self.place):
            raise ValueError(f"BlockPlaces.write: values must be a contiguous array of {len(self.place)} PETSc "
                             "scalars")
        with self.blocks() as addresses:
            for address, mask in zip(addresses, (self._in_diagonal, ~self._in_diagonal)):
                if address:
                    block = (ctypes.c_double * int(np.count_nonzero(mask))).from_address(address)
                    np.ctypeslib.as_array(block)[:] = values[mask]

    @contextmanager
    def blocks(self):
        """The addresses of the diagonal and the off-diagonal block's values (0 for a block with none), for
        writes at :attr:`place`; assembling the matrix afterwards marks it changed."""
        library = petsc_library()
        arrays = [ctypes.c_void_p(), ctypes.c_void_p()]
        taken = []
        try:
            for block, array, mask in zip(self._handles, arrays, (self._in_diagonal, ~self._in_diagonal)):
                if mask.any():
                    error = library.MatSeqAIJGetArray(block, ctypes.byref(array))
                    if error:
                        raise PETSc.Error(error)
                    taken.append((block, array))
            yield tuple(array.value or 0 for array in arrays)
        finally:
            for block, array in taken:
                library.MatSeqAIJRestoreArray(block, ctypes.byref(array))

