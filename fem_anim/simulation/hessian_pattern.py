"""The Hessian's sparsity grown by contact, kept across a checkpoint.

With ``[contact]`` the step Hessian accepts new nonzeros: each pair of surfaces that ever
came near couples dofs the elastic pattern does not (:mod:`fem_anim.contact.ipc`), and PETSc
keeps those entries from then on (as zeros once the pair is gone). The direct solvers'
ordering and pivoting depend on the pattern, so a run that met a contact rounds differently
from one whose matrix never held it: a resumed run must start with the pattern the
uninterrupted run had at its checkpoint to repeat its arithmetic bit for bit.

:func:`extra_couplings` lists the entries of the matrix's pattern that couple vertex dofs
of no common cell, as pairs of dof identities
(:func:`fem_anim.simulation.checkpoint.dof_identity`: partition-independent);
:func:`restore_couplings` inserts zeros there in a new run's matrix. Both are collective.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat

__all__ = ["Blocks", "blocks_of", "extra_couplings", "restore_couplings"]


@dataclass
class Blocks:
    """The unknown's dof blocks as a Hessian's pattern sees them (this rank's).

    Attributes:
        bs: Dofs per block.
        size_global: The number of blocks of the unknown (all ranks).
        global_blocks: The global block of each local block (owned and ghost).
        owned: The local blocks this rank owns.
        cells: For each kind of cell, its local blocks (one row per cell): the couplings
            the cells make.
    """

    bs: int
    size_global: int
    global_blocks: np.ndarray
    owned: np.ndarray
    cells: list[np.ndarray]


def blocks_of(V) -> Blocks:
    """The :class:`Blocks` of a DOLFINx space, or ``V`` itself if it is one already."""
    if isinstance(V, Blocks):
        return V
    index_map = V.dofmap.index_map
    n = index_map.size_local + index_map.num_ghosts
    return Blocks(V.dofmap.index_map_bs, index_map.size_global,
                  np.asarray(index_map.local_to_global(np.arange(n, dtype=np.int32)), np.int64),
                  np.arange(index_map.size_local), [compat.cell_dofs(V)])


def _block_key_table(comm: MPI.Comm, blocks: Blocks, keys: np.ndarray) -> np.ndarray | None:
    """Rank 0: the dof identity of every global block (an array indexed by global block)."""
    parts = comm.gather((blocks.global_blocks[blocks.owned], keys[blocks.owned]), root=0)
    if comm.rank != 0:
        return None
    table = np.empty(blocks.size_global, np.int64)
    for where, values in parts:
        table[where] = values
    return table


def _cell_pairs(blocks: Blocks) -> np.ndarray:
    """Every (row, column) global block pair a cell couples, as row * size_global + column."""
    n_global, made = blocks.size_global, []
    for cells in blocks.cells:
        cell_blocks = blocks.global_blocks[cells]
        k = cell_blocks.shape[1]
        made.append((cell_blocks[:, :, None] * n_global
                     + cell_blocks[:, None, :]).reshape(-1, k * k).ravel())
    return np.unique(np.concatenate(made))


def extra_couplings(A: PETSc.Mat, V, keys: np.ndarray) -> np.ndarray | None:
    """The block couplings of ``A``'s pattern that no cell makes (collective).

    Args:
        A: The assembled Hessian (AIJ, unknown = the displacement space ``V``).
        V: Its space, or the :class:`Blocks` of a joint unknown.
        keys: :func:`~fem_anim.simulation.checkpoint.dof_identity` of ``V`` (one per local
            block).

    Returns:
        On rank 0, an (n, 2) int64 array of (row, column) dof identities, sorted; None
        elsewhere.
    """
    comm = A.getComm().tompi4py()
    if not A.assembled:  # no Newton iteration yet: nothing grew
        return np.zeros((0, 2), np.int64) if comm.rank == 0 else None
    blocks = blocks_of(V)
    bs, n_global = blocks.bs, blocks.size_global
    indptr, cols, _ = A.getValuesCSR()
    start = A.getOwnershipRange()[0]
    rows = start + np.repeat(np.arange(indptr.size - 1), np.diff(indptr))
    pairs = np.unique((rows // bs).astype(np.int64) * n_global + cols // bs)
    extra = pairs[~np.isin(pairs, _cell_pairs(blocks))]
    table = _block_key_table(comm, blocks, keys)
    parts = comm.gather(extra, root=0)
    if comm.rank != 0:
        return None
    extra = np.concatenate(parts)
    out = np.stack([table[extra // n_global], table[extra % n_global]], axis=1)
    return out[np.lexsort((out[:, 1], out[:, 0]))] if out.size else out.reshape(0, 2)


def _insert_zeros(A: PETSc.Mat, blocks: np.ndarray, bs: int) -> None:
    """Add zeros to ``A`` at every dof of the (row, column) global block pairs ``blocks``."""
    comps = np.arange(bs)
    rows = (blocks[:, 0, None, None] * bs + comps[None, :, None]).repeat(bs, 2).ravel()
    cols = (blocks[:, 1, None, None] * bs + comps[None, None, :]).repeat(bs, 1).ravel()
    order = np.argsort(rows, kind="stable")
    rows, cols = rows[order], cols[order]
    unique, first = np.unique(rows, return_index=True)
    A.setValuesIJV(np.r_[first, rows.size].astype(PETSc.IntType), cols.astype(PETSc.IntType),
                   np.zeros(cols.size), addv=PETSc.InsertMode.ADD_VALUES,
                   rowmap=unique.astype(PETSc.IntType))


def restore_couplings(A: PETSc.Mat, V, keys: np.ndarray, couplings: np.ndarray | None) -> None:
    """Give a new run's ``A`` its cells' pattern plus the ``couplings`` of
    :func:`extra_couplings`, as zeros (collective).

    Args:
        A: A new run's Hessian, not yet assembled (it must accept new nonzeros).
        V: Its space, or the :class:`Blocks` of a joint unknown.
        keys: :func:`~fem_anim.simulation.checkpoint.dof_identity` of ``V`` on this run.
        couplings: Rank 0's (row, column) dof identities; None elsewhere.

    Raises:
        KeyError: (on every rank) an identity that is not a dof of this mesh.
    """
    comm = A.getComm().tompi4py()
    blocks = blocks_of(V)
    bs = blocks.bs
    for cells in blocks.cells:
        cell_blocks = blocks.global_blocks[cells]
        k = cell_blocks.shape[1]
        _insert_zeros(A, np.stack([cell_blocks.repeat(k, 1).ravel(),
                                   np.tile(cell_blocks, (1, k)).ravel()], axis=1), bs)
    table = _block_key_table(comm, blocks, keys)
    missing = False
    if comm.rank == 0 and couplings is not None and couplings.size:
        order = np.argsort(table)
        where = np.minimum(np.searchsorted(table[order], couplings), table.size - 1)
        missing = bool(np.any(table[order][where] != couplings))
        if not missing:
            _insert_zeros(A, order[where], bs)
    if comm.bcast(missing, root=0):
        raise KeyError("a contact coupling names a dof this mesh does not have")
    A.assemble()
