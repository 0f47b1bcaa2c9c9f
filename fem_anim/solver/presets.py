"""Linear solver presets: named dictionaries of PETSc options (seed section 3.3).

Each Newton step (seed eq. 10) solves ``H d = -grad g`` with the step Hessian
``H = M + w K(u)`` (``w = h^2/4`` for Newmark): symmetric, and positive definite unless
the elastic Hessian ``K`` is indefinite enough to beat the mass term (large steps, buckling).
A preset is named for what it does; option names carry no prefix (the solver adds
``fem_anim_``). ``fem-anim solvers`` prints them (:func:`describe_presets`).

Precedence (lowest to highest): :data:`NEWTON_DEFAULTS` < preset < scene
``[solver.petsc]`` < command line (:mod:`fem_anim.petsc_options`). The options a preset
gives a component belong to its choice of that component: when a higher layer picks another
``pc_type`` the preset's ``pc_*``, ``sub_*`` and ``mat_mumps_*`` go with it, another
``pc_factor_mat_solver_type`` takes the ``mat_mumps_*``, another ``ksp_type`` its
``ksp_<type>_*`` (:func:`drop_replaced`).

Direct solvers (seed 3.3.1)
---------------------------
The matrix is flagged symmetric, not SPD, so PETSc runs MUMPS in its symmetric mode
SYM = 2 for every ``pc_type cholesky``: an LDL^T factorisation (MUMPS never forms L L^T;
PETSc 3.18 has no option to flag a matrix SPD, which would select SYM = 1). What tells
``cholesky`` and ``ldlt`` apart is numerical pivoting:

* ``cholesky`` sets the pivot threshold CNTL(1) = 0: no pivoting, which is what MUMPS does
  for an SPD matrix. On an SPD Hessian D > 0 and L D^1/2 is the Cholesky factor. It does
  not test definiteness: on an indefinite Hessian it is an unpivoted LDL^T with some
  D_ii < 0 (the inertia is still right), stable only while no pivot is tiny.
* ``ldlt`` keeps threshold pivoting with 1x1 and 2x2 pivots (CNTL(1) = 0.01, MUMPS's default
  for SYM = 2): the factorisation for symmetric indefinite matrices.

Measured, the choice changes neither speed nor results: on the default scene two of 76
factorisations needed 2x2 pivots with ``time.dt = 0.05`` (INFOG(12) > 0), yet both gave the
same Newton iterations and energies to 10 digits, and a StVK run with ``time.dt = 0.1``
fails at step 7 (line search, indefinite Hessian) with both alike.

``cholesky-petsc`` is PETSc's own serial factorisation (U^T D U, no pivoting) with the
fill-reducing ordering AMD (SuiteSparse). On the 8928-dof mesh, fill nnz(factor)/nnz(A) and
time of one factorisation: natural 16.4 / 0.83 s, nd 13.4 / 0.97 s, rcm 13.7 / 0.59 s,
qmd 10.7 / 0.65 s, amd 9.5 / 0.46 s: PETSc's ``nd`` does no better than the natural order
(DOLFINx already numbers the dofs for locality), hence ``amd``. Not being supernodal it
stays 4-5x slower than MUMPS there.

Measured (2 shared cores, PETSc 3.18.5; MUMPS also runs a second BLAS thread): ``solve_wall_s``
summed over the run (assembly included) and, for the direct presets, the factorisations'
part, on the default scene (1788 tets, 1662 dofs, 60 steps, ~178 Newton iterations) and on
``mesh.element_size = 0.025`` (8928 dofs, 10 steps, 30 Newton iterations; the ranges are
repeated runs):

======================== ======================= ======================
preset                   default scene, s        element size 0.025, s
======================== ======================= ======================
cholesky                 3.5-4.9 (factor 1.1-1.7) 5.3-6.3 (factor 2.7-3.1)
ldlt                     3.9-4.2 (factor 1.2-1.3) 5.5-6.1 (factor 2.7-3.1)
lu                       4.1 (factor 1.5)         5.9-6.5 (factor 3.2-3.5)
cholesky-petsc           4.5-4.8 (factor 2.0)     14.5-18.8 (factor 12-16)
cg-jacobi                3.1                      3.1-3.7
cg-sor                   2.9-3.2                  3.3-3.6
cg-icc                   3.0-3.3                  3.2-3.6
gmres-ilu                3.0-3.1                  3.6-3.7
cg-gamg                  4.1-4.2                  4.4-4.9
cg-hypre                 5.0-5.2                  5.1-5.6
richardson-jacobi        6.6                      13.6-13.8
richardson-gauss-seidel  4.3-4.4                  4.5
richardson-sor           3.6-3.8                  3.7
======================== ======================= ======================

The step Hessian is mass dominated at these steps, so a cheap preconditioner is enough and
the Krylov presets beat the factorisations from the default scene on.

Iterative solvers (seed 3.3.2)
------------------------------
Iterations to ``rtol = 1e-10`` for one solve with the Hessian after the last step (random
right-hand side), element size 0.1 / 0.05 / 0.025 (405 / 1662 / 8928 dofs): cg-jacobi
42 / 76 / 128, cg-sor (SSOR, omega = 1) 15 / 26 / 44, cg-icc 12 / 20 / 35, gmres-ilu
12 / 20 / 35 (ILU(0) of a symmetric matrix has ICC(0)'s factors), cg-gamg 11 / 18 / 22,
cg-hypre 11 / 15 / 18. Iterative presets use ``ksp_rtol = 1e-10`` so that Newton takes the
same iterations to the same minimiser as with a direct solve (tests/test_presets.py:
energies within 1.3e-12, displacements within 6e-14 of ``cholesky``).
``solver.forcing = "adaptive"`` (:data:`FORCING`) lets Eisenstat-Walker choose each
Newton iteration's Krylov tolerance instead, at most 1e-2: Newton stops at the same
residual test, on the hanging beam in the same number of iterations, with a third of the
Krylov iterations (12.7k tetrahedra: 377 instead of 993 over 10 steps, 1.3-1.8x faster per
step, tip within 5e-12 of the tight run; fem_anim.bench.options).

Multigrid for elasticity. GAMG builds its coarse spaces from the near-nullspace; without
one it takes the block size 3 of the DOLFINx matrix for three translations. With the six
rigid-body modes attached (``MatSetNearNullSpace``; the problem module does not set them
yet) it needed 10 / 16 / 16 iterations instead of 11 / 18 / 22, and on a stiffness
dominated Hessian (``material.youngs_modulus = 1e7``, ``time.dt = 0.1``) 19 instead of 52.
BoomerAMG gets ``num_functions = 3`` from the block size (the "unknown" approach); PETSc's
default classical coarsening had operator complexity 4.9 on 3D P1 elasticity, so the
preset uses the usual 3D settings (HMIS, ext+i interpolation, at most 4 entries per row
of P, one level of aggressive coarsening): complexity 1.09, more iterations (18 against
10) but half the time. Nodal coarsening (``pc_hypre_boomeramg_nodal_coarsen 6``) did not
help (10 -> 12 iterations with the default coarsening), and ``vec_interp_variant 2``,
which needs the near-nullspace, only got back to the plain setting.

Classical iterations ``P x_{k+1} = (P - A) x_k + b`` converge iff ``rho(I - P^-1 A) < 1``
(seed 3.3.2). Measured, the eigenvalues of ``D^-1 H`` lie in [0.17, 2.45] / [0.058,
2.85] / [0.020, 2.53], so undamped Jacobi (rho = 1.45-1.85) diverges at ``dt = 1/60``.
A fixed damping ``x += s D^-1 r`` converges only for ``s < 2 / lambda_max``, which depends
on the mesh (``s = 0.6`` served the gmsh 4.8 meshes and diverged on a gmsh 4.13 one), so
``richardson-jacobi`` chooses ``s_k`` in every iteration by the seed's line search along
the preconditioned residual (3.3.2, steps 1-3; PETSc's ``ksp_richardson_self_scale``):
it converges for any SPD Hessian at the steepest-descent rate (kappa - 1) / (kappa + 1).
Measured on the default scene (60 steps, DOLFINx 0.5.2, gmsh 4.8): 37 263 iterations and
4.0 s against 91 043 and 7.8 s with ``s = 0.6``; on Debian 13 (gmsh 4.13 mesh, 10 steps)
3 808 against 13 087.
Gauss-Seidel (``P = D + L``) and SOR (``P = D / omega + L``, 0 < omega < 2) converge for
any SPD matrix: measured rates per sweep 0.67 / 0.88 / 0.96 for Gauss-Seidel, and for SOR
with omega = 1.6 (best 1.2 / 1.4 / 1.7) 0.68 / 0.79 / 0.80. PETSc runs Richardson with SOR
as ``ksp_max_it`` sweeps inside ``MatSOR`` without testing the residual
(``PCApplyRichardson_SOR`` ignores ``ksp_rtol`` unless a KSP monitor is set), so for those
two presets ``ksp_max_it`` is the number of sweeps per solve, chosen from these rates: 300
Gauss-Seidel sweeps reduce the error by 2e-17 on the default mesh and 1e-6 at 0.025, 100
SOR sweeps by 6e-11 and 2e-10; ``linear_its`` counts sweeps, and a diverging sweep is
noticed only by Newton.

MPI
---
PETSc's native Cholesky, ICC and ILU exist for one process only, and in parallel SOR only
sweeps within each process (block Jacobi between processes). :func:`preset_options` with
``comm_size > 1`` returns the parallel variant (:func:`parallel_options`): MUMPS for
``cholesky-petsc``, block Jacobi with ICC / ILU blocks for ``cg-icc`` / ``gmres-ilu``,
processor-local sweeps for the SOR presets; ``richardson-sor`` becomes Gauss-Seidel, since
over-relaxed sweeps that lag the other process's values diverged (measured on 2 processes:
rate 1.42 per sweep at omega = 1.6, 1.18 at 1.4). :func:`parallel_note` says what changed.
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = [
    "FORCING",
    "MIXED_ONLY_PRESETS",
    "NEWTON_DEFAULTS",
    "PRESETS",
    "SUMMARY",
    "describe_presets",
    "drop_replaced",
    "forcing_options",
    "parallel_note",
    "parallel_options",
    "preset_options",
]

#: Library defaults of the nonlinear solver: Newton with backtracking on the objective.
NEWTON_DEFAULTS: dict[str, str] = {
    "snes_type": "newtonls",
    "snes_linesearch_type": "bt",
    "snes_rtol": "1e-8",
    "snes_atol": "1e-12",
    "snes_stol": "0",
    "snes_max_it": "50",
}

#: Relative residual reduction of the iterative presets: tight enough that Newton
#: converges in the same iterations, to the same solution, as with a direct solve.
ITERATIVE_RTOL = "1e-10"

#: ``solver.forcing``: the Krylov tolerance of each Newton iteration. ``"tight"`` keeps the
#: presets' ``ksp_rtol`` (1e-10). ``"adaptive"`` is Eisenstat-Walker's choice 2,
#: eta_k = gamma (||g_k|| / ||g_{k-1}||)^alpha capped at 1e-2 (from the first iteration
#: on): Newton still stops at the same residual test (``snes_rtol``, ``snes_atol``), in the
#: same iterations on the hanging beam, with a third of the Krylov iterations
#: (fem_anim.bench.options). PETSc's default EW parameters (eta_0 = 0.3, cap 0.9) cost
#: Newton iterations there: 50 instead of 30 per 10 steps, slower than "tight".
FORCING: dict[str, dict[str, str]] = {
    "tight": {},
    "adaptive": {"snes_ksp_ew": "", "snes_ksp_ew_version": "2", "snes_ksp_ew_rtol0": "1e-2",
                 "snes_ksp_ew_rtolmax": "1e-2"},
}

PRESETS: dict[str, dict[str, str]] = {
    # -- direct (seed 3.3.1) ---------------------------------------------------------------
    "cholesky": {"ksp_type": "preonly", "pc_type": "cholesky",
                 "pc_factor_mat_solver_type": "mumps", "mat_mumps_cntl_1": "0"},
    "ldlt": {"ksp_type": "preonly", "pc_type": "cholesky",
             "pc_factor_mat_solver_type": "mumps", "mat_mumps_cntl_1": "0.01"},
    "lu": {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"},
    "cholesky-petsc": {"ksp_type": "preonly", "pc_type": "cholesky",
                       "pc_factor_mat_solver_type": "petsc",
                       "pc_factor_mat_ordering_type": "amd"},
    # -- Krylov (seed 3.3.2) ---------------------------------------------------------------
    # mat_type baij: the Hessian in d x d blocks, assembled ~3x faster (fem_anim.bench
    # .options: cg-icc 2.1x, cg-jacobi 1.5x per step); Cholesky and GAMG reject it
    "cg-jacobi": {"ksp_type": "cg", "pc_type": "jacobi", "ksp_rtol": ITERATIVE_RTOL,
                  "mat_type": "baij"},
    "cg-sor": {"ksp_type": "cg", "pc_type": "sor", "pc_sor_symmetric": "",
               "ksp_rtol": ITERATIVE_RTOL, "mat_type": "baij"},
    "cg-icc": {"ksp_type": "cg", "pc_type": "icc", "ksp_rtol": ITERATIVE_RTOL,
               "mat_type": "baij"},
    "gmres-ilu": {"ksp_type": "gmres", "pc_type": "ilu", "ksp_rtol": ITERATIVE_RTOL},
    # -- multigrid (seed 3.3.2) ------------------------------------------------------------
    "cg-gamg": {"ksp_type": "cg", "pc_type": "gamg", "ksp_rtol": ITERATIVE_RTOL},
    "cg-hypre": {"ksp_type": "cg", "pc_type": "hypre", "pc_hypre_type": "boomeramg",
                 "pc_hypre_boomeramg_coarsen_type": "HMIS",
                 "pc_hypre_boomeramg_interp_type": "ext+i", "pc_hypre_boomeramg_P_max": "4",
                 "pc_hypre_boomeramg_agg_nl": "1", "ksp_rtol": ITERATIVE_RTOL},
    # -- classical iterations P x_{k+1} = (P - A) x_k + b (seed 3.3.2) -----------------------
    "richardson-jacobi": {"ksp_type": "richardson", "ksp_richardson_self_scale": "",
                          "pc_type": "jacobi", "ksp_rtol": ITERATIVE_RTOL,
                          "ksp_max_it": "5000"},
    "richardson-gauss-seidel": {"ksp_type": "richardson", "pc_type": "sor",
                                "pc_sor_forward": "", "ksp_rtol": ITERATIVE_RTOL,
                                "ksp_max_it": "300"},
    "richardson-sor": {"ksp_type": "richardson", "pc_type": "sor", "pc_sor_forward": "",
                       "pc_sor_omega": "1.6", "ksp_rtol": ITERATIVE_RTOL,
                       "ksp_max_it": "100"},
}

#: Presets for the saddle point of element.formulation = "mixed" only (fem_anim.problem.mixed_space): PETSc
#: fieldsplit with the fields u and p~ (index sets from the mixed space, set by
#: EnergyProblem.configure_preconditioner), the full Schur factorisation
#: [[A, 0], [B, S]] [[I, A^-1 B^T], [0, I]], A^-1 by one BoomerAMG V-cycle, S^-1 by one Jacobi
#: application of the user matrix -w mu (1 + mu/kappa) M_p (the pressure mass) standing in for S;
#: FGMRES outside, since the preconditioner is not a fixed linear map.
MIXED_ONLY_PRESETS: dict[str, dict[str, str]] = {
    "schur": {"ksp_type": "fgmres", "ksp_rtol": ITERATIVE_RTOL, "ksp_max_it": "500",
              "ksp_gmres_restart": "100", "pc_type": "fieldsplit",
              "pc_fieldsplit_type": "schur", "pc_fieldsplit_schur_fact_type": "full",
              "pc_fieldsplit_schur_precondition": "user",
              "fieldsplit_u_ksp_type": "preonly", "fieldsplit_u_pc_type": "hypre",
              "fieldsplit_u_pc_hypre_type": "boomeramg",
              "fieldsplit_p_ksp_type": "preonly", "fieldsplit_p_pc_type": "jacobi"},
}

SUMMARY: dict[str, str] = {
    "cholesky": "sparse Cholesky (MUMPS LDL^T without pivoting, for an SPD Hessian), "
                "seed 3.3.1; the default",
    "ldlt": "sparse symmetric indefinite LDL^T (MUMPS, 1x1/2x2 threshold pivoting), seed 3.3.1",
    "lu": "sparse LU with threshold partial pivoting (MUMPS), seed 3.3.1",
    "cholesky-petsc": "PETSc's own serial sparse Cholesky with the AMD fill-reducing ordering",
    "cg-jacobi": "conjugate gradients, Jacobi (diagonal) preconditioner, seed 3.3.2",
    "cg-sor": "conjugate gradients, symmetric Gauss-Seidel (SSOR) preconditioner, seed 3.3.2",
    "cg-icc": "conjugate gradients, incomplete Cholesky ICC(0) preconditioner, seed 3.3.2",
    "gmres-ilu": "GMRES, incomplete LU ILU(0) preconditioner",
    "cg-gamg": "conjugate gradients, smoothed-aggregation algebraic multigrid (GAMG)",
    "cg-hypre": "conjugate gradients, classical algebraic multigrid (hypre BoomerAMG)",
    "richardson-jacobi": "Jacobi iteration x += s_k D^-1 r_k, its damping s_k from the "
                         "seed's line search each iteration (3.3.2; undamped it diverges)",
    "richardson-gauss-seidel": "classical Gauss-Seidel, P = D + L: 300 forward sweeps per "
                               "solve, seed 3.3.2",
    "richardson-sor": "classical SOR, P = D / omega + L, omega = 1.6: 100 forward sweeps "
                      "per solve, seed 3.3.2",
    "schur": "element.formulation = \"mixed\" only: FGMRES, fieldsplit Schur complement, "
             "BoomerAMG on u, pressure mass for S",
}

#: Serial-only factorisations and their parallel replacements (block Jacobi: one block
#: per process, factorised incompletely there).
_BLOCK_JACOBI = {"icc", "ilu"}
_SOR_SWEEPS = {"pc_sor_symmetric": "pc_sor_local_symmetric",
               "pc_sor_forward": "pc_sor_local_forward",
               "pc_sor_backward": "pc_sor_local_backward"}

#: Over-relaxed sweeps that lag the other processes' values diverge (measured on 2
#: processes: rate 1.42 per sweep at omega = 1.6, 1.18 at 1.4); Gauss-Seidel converges.
_PARALLEL_OVERRIDES = {
    "richardson-sor": ({"pc_sor_omega": "1", "ksp_max_it": "300"},
                       ("over-relaxation diverges across process boundaries: omega = 1 "
                        "(processor-local Gauss-Seidel, as richardson-gauss-seidel)")),
}

#: Options that belong to a component: replacing the component in a higher layer drops them.
_COMPONENT_OPTIONS = {
    "pc_type": ("pc_", "sub_", "mat_mumps_", "mat_type"),
    "pc_factor_mat_solver_type": ("mat_mumps_",),
}


def _parallel_variant(name: str, options: Mapping[str, str]) -> tuple[dict[str, str], list[str]]:
    """The options with every serial-only choice replaced, and what was replaced."""
    out = dict(options)
    notes: list[str] = []
    pc = out.get("pc_type")
    solver = out.get("pc_factor_mat_solver_type", "petsc")
    if pc in ("cholesky", "lu") and solver == "petsc":
        out = {k: v for k, v in out.items() if not k.startswith("pc_factor_")}
        out["pc_factor_mat_solver_type"] = "mumps"
        if pc == "cholesky":
            out["mat_mumps_cntl_1"] = "0"
        notes.append(f"PETSc's native {pc} is serial: MUMPS {pc} instead (preset {pc!r})")
    elif pc in _BLOCK_JACOBI:
        sub = {f"sub_{k}": v for k, v in out.items() if k.startswith("pc_factor_")}
        out = {k: v for k, v in out.items() if not k.startswith("pc_factor_")}
        out.update(pc_type="bjacobi", sub_pc_type=pc, **sub)
        notes.append(f"{pc.upper()} is serial: block Jacobi with one {pc.upper()} block per "
                     "process (iterations grow with the number of processes)")
    elif pc == "sor":
        out = {_SOR_SWEEPS.get(k, k): v for k, v in out.items()}
        notes.append("SOR sweeps only within each process (block Jacobi between "
                     "processes, SOR inside): a different, usually slower iteration")
    if name in _PARALLEL_OVERRIDES:
        changes, note = _PARALLEL_OVERRIDES[name]
        out.update(changes)
        notes.append(note)
    return out, notes


def parallel_options(name: str, options: Mapping[str, str], comm_size: int) -> dict[str, str]:
    """The parallel-safe variant of a preset's options for ``comm_size`` processes.

    PETSc's native (``pc_factor_mat_solver_type petsc``) Cholesky and LU become MUMPS;
    ICC and ILU become block Jacobi with ICC/ILU blocks (``sub_pc_type``); global SOR
    sweeps become processor-local ones (``pc_sor_local_*``). Options that run in parallel
    as they are come back unchanged, as do all options for ``comm_size == 1``.

    Args:
        name: The preset's name (for the messages of :func:`parallel_note`).
        options: The preset's options.
        comm_size: Number of MPI processes.
    """
    if comm_size <= 1:
        return dict(options)
    return _parallel_variant(name, options)[0]


def parallel_note(name: str, comm_size: int = 2) -> str:
    """What :func:`preset_options` changes in preset ``name`` under MPI ("" if nothing)."""
    if comm_size <= 1:
        return ""
    notes = _parallel_variant(name, _lookup(name))[1]
    return f"solver preset {name!r} on {comm_size} processes: " + "; ".join(notes) \
        if notes else ""


def _lookup(name: str) -> dict[str, str]:
    known = PRESETS | MIXED_ONLY_PRESETS
    if name not in known:
        raise KeyError(f"unknown solver preset {name!r} (known: {', '.join(known)})")
    return known[name]


def preset_options(name: str, comm_size: int = 1) -> dict[str, str]:
    """The options of a preset, in the parallel-safe variant when ``comm_size > 1``.

    Raises:
        KeyError: with the known names, if ``name`` is not a preset.
    """
    return parallel_options(name, _lookup(name), comm_size)


def forcing_options(forcing: str, options: Mapping[str, str]) -> dict[str, str]:
    """The options of ``solver.forcing`` for a solver whose merged options are ``options``.

    Raises:
        ValueError: ``"adaptive"`` with a solver that has no Krylov tolerance to adapt
            (a direct ``preonly`` solve, or a Richardson iteration that runs a fixed
            number of SOR sweeps).
    """
    if forcing == "tight":
        return {}
    ksp, pc = options.get("ksp_type"), options.get("pc_type")
    if ksp == "preonly" or (ksp == "richardson" and pc == "sor"):
        what = "a direct solve" if ksp == "preonly" else "a fixed number of SOR sweeps"
        raise ValueError(f"solver.forcing = {forcing!r} adapts the Krylov tolerance; "
                         f"this solver (ksp_type {ksp}, pc_type {pc}) is {what}: use a "
                         "Krylov preset (cg-icc, cg-jacobi, cg-hypre, ...)")
    return dict(FORCING[forcing])


def drop_replaced(layer: Mapping[str, str], above: Mapping[str, str]) -> dict[str, str]:
    """A preset's options without those of components a higher layer replaces.

    A preset's ``pc_*``, ``sub_*`` and ``mat_mumps_*`` options describe its preconditioner:
    when ``above`` (scene and command line) sets another ``pc_type`` they are dropped
    (``-pc_type icc`` on top of ``cholesky`` is ICC, not "ICC by MUMPS"); another
    ``pc_factor_mat_solver_type`` drops the ``mat_mumps_*``; another ``ksp_type`` drops the
    preset's ``ksp_<type>_*`` (e.g. ``ksp_richardson_scale``). Unused options would
    otherwise be left in PETSc's database (``-options_left``).
    """
    out = dict(layer)
    for key, prefixes in _COMPONENT_OPTIONS.items():
        if key in out and above.get(key, out[key]) != out[key]:
            out = {k: v for k, v in out.items() if not k.startswith(prefixes)}
    ksp = out.get("ksp_type")
    if ksp is not None and above.get("ksp_type", ksp) != ksp:
        out = {k: v for k, v in out.items() if not k.startswith(f"ksp_{ksp}_")}
    return out


def describe_presets() -> str:
    """A human-readable list of the presets and their options (``fem-anim solvers``)."""
    lines = [("Linear solver presets (--solver NAME or solver.preset); options without the "
              "fem_anim_ prefix."),
             "Precedence: defaults < preset < scene [solver.petsc] < command line.", ""]
    for name, options in (PRESETS | MIXED_ONLY_PRESETS).items():
        lines.append(f"{name}: {SUMMARY[name]}")
        lines += [f"    -{k} {v}".rstrip() for k, v in options.items()]
        parallel = preset_options(name, comm_size=2)
        if parallel != options:
            shown = " ".join(f"-{k} {v}".rstrip() for k, v in parallel.items())
            lines.append(f"    under MPI: {shown}")
    return "\n".join(lines)
