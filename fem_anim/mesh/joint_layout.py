"""Several function spaces as one unknown: the joint numbering of their dofs under MPI.

A shell and a solid are two DOLFINx meshes (one cell type per mesh), so their step's
unknown x = (x_s, x_c) lives in two spaces; the step is still one minimisation over x (seed
eq. 4; docs/notes/shell_solid_coupling.md). :class:`JointLayout` numbers x's dof blocks
rank by rank, the layout of DOLFINx's ``create_vector_block``: rank r holds its owned
blocks of the first space, then its owned blocks of the second, ..., and its range starts
after all blocks of the lower ranks. Each rank's local part of a joint vector is so the
concatenation of the spaces' owned entries, and each rank owns one contiguous range of
global blocks (what :mod:`fem_anim.contact.distribution` needs of a numbering).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

__all__ = ["JointLayout"]


class JointLayout:
    """The joint block numbering of several spaces (collective to build).

    Args:
        comm: The communicator of every space's mesh.
        spaces: Function spaces with the same block size (3: displacements in 3D).

    Attributes:
        owned: Each space's owned blocks on this rank.
        offsets: Where each space's owned entries start in this rank's local joint array
            (unblocked: block size times the blocks before).
        start: This rank's first joint block.
        n_owned: This rank's owned joint blocks (the sum of ``owned``).
        size: The global number of joint blocks.
        bs: The block size.
    """

    def __init__(self, comm: MPI.Comm, spaces: list):
        self.comm = comm
        sizes = {V.dofmap.index_map_bs for V in spaces}
        if len(sizes) != 1:
            raise ValueError(f"spaces of one joint unknown need one block size, got {sizes}")
        self.bs = sizes.pop()
        self._maps = [V.dofmap.index_map for V in spaces]
        self.owned = [m.size_local for m in self._maps]
        every = np.asarray(comm.allgather(np.array(self.owned, np.int64)))
        self._every = every.reshape(comm.size, len(spaces))  # (ranks, spaces)
        totals = self._every.sum(axis=1)
        self._rank_start = np.r_[0, np.cumsum(totals)[:-1]]
        self._inside = np.c_[np.zeros(comm.size, np.int64),
                             np.cumsum(self._every, axis=1)[:, :-1]]
        self.start = int(self._rank_start[comm.rank])
        self.n_owned = int(sum(self.owned))
        self.size = int(totals.sum())
        self.offsets = [self.bs * int(o) for o in np.r_[0, np.cumsum(self.owned)[:-1]]]

    def joint_of_global(self, k: int, blocks: np.ndarray) -> np.ndarray:
        """The joint blocks of global blocks of space ``k`` (any rank's)."""
        blocks = np.asarray(blocks, np.int64)
        ends = np.cumsum(self._every[:, k])
        owner = np.searchsorted(ends, blocks, side="right")
        first = ends[owner] - self._every[owner, k]
        return self._rank_start[owner] + self._inside[owner, k] + blocks - first

    def joint_of_local(self, k: int) -> np.ndarray:
        """The joint block of every local block (owned, then ghosts) of space ``k``."""
        m = self._maps[k]
        local = np.arange(m.size_local + m.num_ghosts, dtype=np.int32)
        return self.joint_of_global(k, m.local_to_global(local))

    def joint_dofs_of_global(self, k: int, dofs: np.ndarray) -> np.ndarray:
        """The joint (unblocked) indices of global (unblocked) dofs of space ``k``."""
        dofs = np.asarray(dofs, np.int64)
        return self.joint_of_global(k, dofs // self.bs) * self.bs + dofs % self.bs

    def local_slice(self, k: int) -> slice:
        """Space ``k``'s owned entries in this rank's local joint array (unblocked)."""
        return slice(self.offsets[k], self.offsets[k] + self.bs * self.owned[k])
