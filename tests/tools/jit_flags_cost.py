"""What gcc flags cost: compile and assembly of a Kirchhoff-Love step objective (docs/cloth.md).

Builds the membrane + Kirchhoff-Love bending energy of a P2 sheet (1 x 0.25 m, 64 x 16
squares, right triangles, a smooth bend; the material, thickness, D and nu as Constants, as
the package's scenes hold them), and compiles its residual and tangent into one module
(:func:`fem_anim.compat.compile_forms_together`, as the package does) once per flag set given
on the command line, each into a cache folder of its own (under ``--cache``, default a new
temporary folder: a folder given again reuses the compiled modules). It prints per flag set
the compile's wall time and gcc's CPU time, then, timed in turns (eleven rounds of three
assemblies), the residual + tangent assembly's fastest and median time in this process's
CPU seconds (the assembly is serial; CPU time is what a loaded machine disturbs least)::

    .venv/bin/python tests/tools/jit_flags_cost.py "-O2 -g0 -march=native" \\
        "-O2 -g0 -march=native -fno-schedule-insns2" "-O1 -g0 -march=native"
    bash .ci/debian13 .venv/bin/python tests/tools/jit_flags_cost.py ...   # on Debian 13
"""

from __future__ import annotations

import argparse
import resource
import tempfile
import time
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.forms.lame import lame_parameters
from fem_anim.forms.shell_bending import flexural_rigidity
from fem_anim.meshes.sheet import structured_sheet
from fem_anim.problem.shell_terms import ShellEnergy, shell_measures


def _gcc_seconds() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def main(flag_sets: list[str], cache_root: Path) -> None:
    """Compile and time the objective's residual and tangent with each flag set."""
    n = 64
    points, cells = structured_sheet([1.0, 0.25], [n, n // 4], None, "right")
    mesh = compat.create_mesh(MPI.COMM_SELF, cells, points, 3, "triangle")
    V = compat.vector_space(mesh, 2)
    u = fem.Function(V)
    u.interpolate(lambda y: np.vstack([0 * y[0], 0 * y[0], 0.01 * y[0] ** 2 + 0.003 * y[1]]))

    def constant(value):
        return fem.Constant(mesh, PETSc.ScalarType(value))

    mu, lmbda = lame_parameters(1e10, 0.3)
    shell = ShellEnergy("stvk", constant(mu), constant(lmbda), constant(0.01),
                        constant(flexural_rigidity(1e10, 0.3, 0.01)), "kirchhoff_love",
                        constant(0.3))
    dx, dS = shell_measures(mesh, 2)
    energy = shell.energy(u, dx, dS)
    forms = {"residual": ufl.derivative(energy, u),
             "tangent": ufl.derivative(ufl.derivative(energy, u), u)}
    compiled = {}
    for flags in flag_sets:
        cache = cache_root / "_".join(flags.split())
        start, gcc = time.perf_counter(), _gcc_seconds()
        compiled[flags] = compat.compile_forms_together(
            forms, {"cffi_extra_compile_args": flags.split(), "cache_dir": str(cache)})
        print(f"{flags}: compile {time.perf_counter() - start:.1f} s, gcc CPU "
              f"{_gcc_seconds() - gcc:.1f} s ({cache})", flush=True)
        fem_petsc.assemble_matrix(compiled[flags]["tangent"]).assemble()  # warm up
    times = {flags: [] for flags in compiled}
    for _ in range(11):
        for flags, c in compiled.items():
            start = time.process_time()
            for _ in range(3):
                A = fem_petsc.assemble_matrix(c["tangent"])
                A.assemble()
                A.destroy()
                fem_petsc.assemble_vector(c["residual"]).destroy()
            times[flags].append((time.process_time() - start) / 3)
    dofs = V.dofmap.index_map.size_local * 3
    for flags, t in times.items():
        print(f"{flags}: residual + tangent assembly ({dofs} dofs) fastest "
              f"{min(t) * 1e3:.1f} ms, median {sorted(t)[len(t) // 2] * 1e3:.1f} ms (CPU)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("flags", nargs="+", help="gcc flags, one quoted set per argument")
    parser.add_argument("--cache", type=Path, help="folder of the flag sets' JIT caches")
    args = parser.parse_args()
    main(args.flags, args.cache or Path(tempfile.mkdtemp(prefix="jit_flags_cost_")))
