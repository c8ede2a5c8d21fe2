"""A Cholesky factor that is cheap to keep: the preconditioner of the ``cholesky-reuse`` preset.

The displacement matrix changes a little every increment (g(phi) moves) and a lot only where
the crack runs. Kept across increments (``displacement_reuse``, fem/problem.py
PreconditionerReuse), the factor of an earlier matrix is a preconditioner that CG needs a few
iterations with; that pays only if applying the factor is cheap. MUMPS factors fast and applies
slowly (snt1, 80k dofs, one core: 0.118 s a factor, 22 ms an apply); PETSc's own Cholesky of
the AIJ matrix applies fast and factors slowly (0.33 s, 6.2 ms). PETSc's block (SBAIJ, 2x2
blocks) Cholesky has both (0.16 s, 6.9 ms), but takes no fill-reducing ordering of its own: this
preconditioner permutes the matrix by nested dissection (computed once: the pattern never
changes), converts it to SBAIJ and factors that; an apply permutes in and out
(docs/decisions.md, "A kept Cholesky factor").

Select it as a PETSc python preconditioner::

    displacement: {ksp_type: cg, pc_type: python,
                   pc_python_type: ifenn.fem.factor.NestedDissectionCholesky, ...}

In parallel (PETSc's own Cholesky is serial) it factors with MUMPS instead: same answer.
"""

from __future__ import annotations

import atexit

import numpy as np
from petsc4py import PETSc

#: the preconditioners using this context. PETSc destroys at PetscFinalize what Python left it
#: (petsc4py delays the destruction of collected objects), after the interpreter is gone: a python
#: PC would call back into it there and crash the process at exit, its outputs written (exit code
#: 59: a failed job to snakemake). So each is kept here and detached before, at exit; the collected
#: ones are destroyed while Python still runs (garbage_cleanup).
_IN_USE: list[PETSc.PC] = []


@atexit.register
def _detach() -> None:
    import gc

    gc.collect()
    PETSc.garbage_cleanup()
    for pc in _IN_USE:
        if pc.handle:
            pc.setType(PETSc.PC.Type.NONE)
            pc.destroy()
    _IN_USE.clear()
    PETSc.garbage_cleanup()


def as_blocks(A: PETSc.Mat, bs: int) -> PETSc.Mat:
    """A serial AIJ matrix whose entries come in dense ``bs`` x ``bs`` blocks (rows bs i .. bs i +
    bs - 1 share one column pattern, made of whole blocks: Q1 displacements, node by node), as a
    new BAIJ matrix: the same values, gathered by index arithmetic. PETSc's own conversion visits
    the entries one by one (seconds at 50k dofs; this: tens of milliseconds)."""
    indptr, indices, data = A.getValuesCSR()
    start = indptr[0:-1:bs]
    length = indptr[1::bs] - start                   # entries of each block row's first row
    if A.getSize()[0] % bs or (length % bs).any() or any(not np.array_equal(indptr[k + 1::bs] - indptr[k::bs], length)
                                                        for k in range(1, bs)):
        raise ValueError(f"the matrix's pattern is not made of {bs} x {bs} blocks")
    blocks = length // bs
    block_ptr = np.concatenate([[0], np.cumsum(blocks)])
    first = np.repeat(start, blocks) + bs * (np.arange(block_ptr[-1]) - np.repeat(block_ptr[:-1], blocks))
    rows = [first + k * np.repeat(length, blocks) for k in range(bs)]     # each block's first entry, row by row
    values = np.stack([data[row + j] for row in rows for j in range(bs)], axis=1)
    if any((indices[row + j] != indices[first] + j).any() for row in rows for j in range(bs)) or (indices[first] % bs).any():
        raise ValueError(f"the matrix's pattern is not made of {bs} x {bs} blocks")
    return PETSc.Mat().createBAIJ(A.getSize(), bs, csr=(block_ptr.astype(PETSc.IntType), (indices[first] // bs).astype(PETSc.IntType),
                                                       values.ravel()), comm=PETSc.COMM_SELF)


class NestedDissectionCholesky:
    """petsc4py python-PC context: y = (P^T L L^T P)^-1 x with P the nested-dissection order.

    The fast path needs the operator as a serial BAIJ matrix (``displacement_matrix: baij`` in
    the preset): BAIJ permutes and converts to SBAIJ in ~15 ms, AIJ to SBAIJ takes 2.5 s (PETSc
    converts a blocked AIJ entry by entry). An AIJ operator is factored by PETSc's AIJ Cholesky
    in nested-dissection order, a parallel one by MUMPS: slower, the same answer.
    """

    def __init__(self):
        self.inner: PETSc.KSP | None = None
        self.blocks: PETSc.IS | None = None      # the nested-dissection order of the 2x2 blocks
        self.order: np.ndarray | None = None     # row k of the permuted matrix is row order[k]
        self.factored: PETSc.Mat | None = None   # the permuted SBAIJ matrix the inner KSP factors
        self.x_permuted = self.y_permuted = None
        self.factorizations = 0

    def create(self, pc: PETSc.PC) -> None:
        _IN_USE.append(pc)

    def _create(self, A: PETSc.Mat) -> None:
        self.inner = PETSc.KSP().create(A.getComm())
        self.inner.setType(PETSc.KSP.Type.PREONLY)
        pc = self.inner.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        if A.getComm().getSize() > 1:
            pc.setFactorSolverType("mumps")
        elif A.getType() == PETSc.Mat.Type.SEQBAIJ and A.getBlockSize() > 1:
            pc.setFactorSolverType("petsc")
            pc.setFactorOrdering("natural")   # the matrix comes in nested-dissection order
            block_order = A.getOrdering("nd")[0].getIndices()
            self.blocks = PETSc.IS().createBlock(A.getBlockSize(), block_order)
            self.order = self.blocks.getIndices().astype(np.int64)
        else:
            pc.setFactorSolverType("petsc")
            pc.setFactorOrdering("nd")

    def setUp(self, pc: PETSc.PC) -> None:
        A = pc.getOperators()[1]
        if self.inner is None:
            self._create(A)
        if self.order is None:
            self.inner.setOperators(A)
        else:
            permuted = A.permute(self.blocks, self.blocks)
            permuted.setOption(PETSc.Mat.Option.SYMMETRIC, True)
            permuted.convert(PETSc.Mat.Type.SBAIJ)   # in place: the fast conversion
            if self.factored is None:
                self.factored = permuted
                self.x_permuted, self.y_permuted = permuted.createVecs()
            else:   # same pattern: the factor's symbolic part is kept
                permuted.copy(self.factored, PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
                permuted.destroy()
            self.inner.setOperators(self.factored)
        inner_pc = self.inner.getPC()
        inner_pc.setReusePreconditioner(False)
        self.inner.setUp()
        # kept until the next setUp: on the AIJ and MUMPS paths the inner operator is the outer
        # matrix, whose new values would otherwise refactor it at every apply (a fresh factor each
        # CG iteration: exact, and as slow as a direct solve each iteration)
        inner_pc.setReusePreconditioner(True)
        self.factorizations += 1

    def apply(self, pc: PETSc.PC, x: PETSc.Vec, y: PETSc.Vec) -> None:
        if self.order is None:
            self.inner.solve(x, y)
            return
        self.x_permuted.array[:] = x.array_r[self.order]
        self.inner.solve(self.x_permuted, self.y_permuted)
        y.array[self.order] = self.y_permuted.array_r

    def destroy(self, pc: PETSc.PC) -> None:
        for obj in (self.inner, self.factored, self.x_permuted, self.y_permuted, self.blocks):
            if obj is not None:
                obj.destroy()
        self.inner = self.factored = self.x_permuted = self.y_permuted = self.blocks = None

    def view(self, pc: PETSc.PC, viewer: PETSc.Viewer) -> None:
        kind = "MUMPS" if self.inner is not None and self.inner.getComm().getSize() > 1 else (
            "SBAIJ, nested-dissection blocks" if self.order is not None else "AIJ, nested dissection")
        viewer.printfASCII(f"  Cholesky ({kind}), {self.factorizations} factorizations\n")
