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


class BlockRuns:
    """New values of a parallel AIJ matrix, in the order of the local CSR rows it was made from
    (``createAIJWithArrays``, sorted columns), written into PETSc's diagonal and off-diagonal blocks by whole
    runs of entries.

    Each block keeps the rows' order with the other block's entries left out, so between two entries of the
    other block a run is one copy (``copy_runs``: the compiled ``primordia_copy_runs``, a ``memcpy`` each);
    ``MatUpdateMPIAIJWithArray`` copies each row's three segments by itself: 64 against 30 us for 103k entries
    on 2 ranks (a 172^2 seven-point matrix, the size of example 1a's fitted operator at 171^2, session of
    2026-12-05).  The same order numbers each entry's place in the blocks (:meth:`targets`), so code that
    computes the values one by one can write them there itself (:meth:`blocks`), with no copy at all.
    Made by :meth:`of`, which checks the order on the matrix itself.
    """

    def __init__(self, matrix, in_diagonal: np.ndarray, copy_runs):
        library = petsc_library()
        diagonal, off_diagonal, columns_map = ctypes.c_void_p(), ctypes.c_void_p(), ctypes.c_void_p()
        error = library.MatMPIAIJGetSeqAIJ(matrix.handle, ctypes.byref(diagonal), ctypes.byref(off_diagonal),
                                           ctypes.byref(columns_map))
        if error:
            raise PETSc.Error(error)
        self._matrix, self._copy_runs = matrix, copy_runs  # the blocks live as long as the matrix
        self._size = len(in_diagonal)
        self._in_diagonal = in_diagonal
        self._handles = (diagonal, off_diagonal)
        self._blocks = [(block, _runs(mask)) for block, mask in ((diagonal, in_diagonal),
                                                                 (off_diagonal, ~in_diagonal)) if mask.any()]

    @classmethod
    def of(cls, matrix, columns: np.ndarray, copy_runs) -> "BlockRuns | None":
        """The runs of ``matrix`` (``columns``: the global column of each local entry, sorted in each row), or
        None on every rank if on any rank the matrix does not read back, by rows, what the runs wrote
        (collective).  Leaves every value zero.

        The runs are copied into PETSc's own arrays: a block holding fewer entries than ``columns`` puts in it
        would be written past its end before anything could be read back, so the blocks' sizes are compared
        with ``columns`` first, and a matrix whose sizes differ on any rank is not written at all."""
        start, end = matrix.getOwnershipRangeColumn()
        in_diagonal = (columns >= start) & (columns < end)
        diagonal_entries = matrix.getDiagonalBlock().getInfo()["nz_used"]
        local_entries = matrix.getInfo(PETSc.Mat.InfoType.LOCAL)["nz_used"]
        fits = diagonal_entries == np.count_nonzero(in_diagonal) and local_entries == len(columns)
        if not all(matrix.getComm().tompi4py().allgather(fits)):
            return None
        runs = cls(matrix, in_diagonal, copy_runs)
        numbered = np.arange(1.0, len(columns) + 1.0, dtype=PETSc.ScalarType)
        runs.write(numbered)
        matrix.assemble()
        ordered = bool(np.array_equal(matrix.getValuesCSR()[2], numbered))
        runs.write(np.zeros(len(columns), dtype=PETSc.ScalarType))
        matrix.assemble()
        return runs if all(matrix.getComm().tompi4py().allgather(ordered)) else None

    def write(self, values: np.ndarray) -> None:
        """``values`` (contiguous PETSc scalars, in the rows' order) into the blocks; assembling the matrix
        then marks it changed."""
        if values.dtype != PETSc.ScalarType or not values.flags.c_contiguous or len(values) != self._size:
            raise ValueError(f"BlockRuns.write: values must be a contiguous array of {self._size} PETSc scalars")
        library = petsc_library()
        for block, (count, source, target, length) in self._blocks:
            array = ctypes.c_void_p()
            error = library.MatSeqAIJGetArray(block, ctypes.byref(array))
            if error:
                raise PETSc.Error(error)
            self._copy_runs(count, source.ctypes.data, target.ctypes.data, length.ctypes.data, values.ctypes.data,
                            array.value)
            library.MatSeqAIJRestoreArray(block, ctypes.byref(array))

    def targets(self) -> tuple[np.ndarray, int]:
        """(place, split): each local entry's place in the blocks, in the rows' order, and the diagonal block's
        size.  A place below ``split`` is the entry's position in the diagonal block's values, one at or above
        it ``split`` past its position in the off-diagonal block's."""
        place = np.empty(self._size, dtype=np.int64)
        split = int(np.count_nonzero(self._in_diagonal))
        place[self._in_diagonal] = np.arange(split)
        place[~self._in_diagonal] = split + np.arange(self._size - split)
        return place, split

    @contextmanager
    def blocks(self):
        """The addresses of the diagonal and the off-diagonal block's values (0 for a block with none), for
        writes at the places of :meth:`targets`; assembling the matrix afterwards marks it changed."""
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


def _runs(mask: np.ndarray) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
    """(count, sources, targets, lengths) of the maximal runs of consecutive entries where ``mask`` holds: their
    positions among all entries and among the masked ones."""
    chosen = np.flatnonzero(mask)
    breaks = np.flatnonzero(np.diff(chosen) != 1) + 1
    starts, ends = np.r_[0, breaks], np.r_[breaks, len(chosen)]
    return (len(starts), chosen[starts].astype(np.int64), starts.astype(np.int64),
            (ends - starts).astype(np.int64))
