"""Linear-solver presets: named dictionaries of PETSc options (seed section 3.3).

Each Newton iteration (seed eq. 10) solves H d = r with the step Hessian H = M + w K(u)
(w = h^2/4 for Newmark): symmetric, and positive definite unless the elastic Hessian K is
indefinite enough to beat the mass term. A *preset* is a name (``solver.preset`` or
``--solver NAME``) for one choice of linear solver, given as PETSc options without the
solver's prefix; ``fem-anim solvers`` prints them (:func:`describe_presets`).

Precedence, lowest to highest: :data:`NEWTON_DEFAULTS` < preset < ``solver.forcing``
(:func:`forcing_options`) < scene ``[solver.petsc]`` < command line
(:mod:`fem_anim.petsc_options`). A preset's options for a component belong to its choice of
that component: a higher layer that picks another ``pc_type``, factorisation package or
``ksp_type`` drops them (:func:`drop_replaced`). Under MPI, :func:`preset_options` returns
the parallel-safe variant of a serial-only choice (:func:`parallel_options`) and
:func:`parallel_note` says what changed.

Presets (:data:`PRESETS`; one line each in :data:`SUMMARY`):

* direct (seed 3.3.1): ``cholesky`` (the default: MUMPS LDL^T without pivoting, exact for an
  SPD Hessian), ``ldlt`` (MUMPS LDL^T with 1x1/2x2 threshold pivoting, for an indefinite
  one), ``lu`` (MUMPS LU), ``cholesky-petsc`` (PETSc's serial Cholesky, AMD ordering);
* Krylov (seed 3.3.2): ``cg-jacobi``, ``cg-sor`` (SSOR), ``cg-icc`` (ICC(0)),
  ``gmres-ilu`` (ILU(0)), with ``ksp_rtol = 1e-10`` so that Newton takes the same
  iterations to the same minimiser as with a direct solve;
* multigrid: ``cg-gamg`` (smoothed aggregation), ``cg-hypre`` (BoomerAMG, 3D settings);
* classical iterations P x_{k+1} = (P - A) x_k + b (seed 3.3.2): ``richardson-jacobi``
  (Jacobi damped by the seed's line search along the preconditioned residual each
  iteration), ``richardson-gauss-seidel`` (300 forward sweeps per solve) and
  ``richardson-sor`` (omega = 1.6, 100 sweeps): for the last two ``ksp_max_it`` is the
  number of sweeps, PETSc testing no residual between them;
* ``schur`` (:data:`MIXED_ONLY_PRESETS`): the saddle point of
  ``element.formulation = "mixed"`` only, FGMRES with a fieldsplit Schur complement.
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
#: on): Newton still stops at the same residual test (``snes_rtol``, ``snes_atol``).
FORCING: dict[str, dict[str, str]] = {
    "tight": {},
    "adaptive": {"snes_ksp_ew": "", "snes_ksp_ew_version": "2", "snes_ksp_ew_rtol0": "1e-2",
                 "snes_ksp_ew_rtolmax": "1e-2"},
}

#: The presets of every formulation: name -> PETSc options without prefix.
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
    # mat_type baij: the Hessian in d x d blocks, assembled faster; Cholesky and GAMG
    # reject it
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

#: Presets for the saddle point of element.formulation = "mixed" only
#: (:mod:`fem_anim.problem.mixed_space`): PETSc fieldsplit with the fields u and p~ (index
#: sets from the mixed space, set by EnergyProblem.configure_preconditioner), the full Schur
#: factorisation
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

#: One line per preset (``fem-anim solvers``).
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

#: Over-relaxed sweeps that lag the other processes' values diverge; Gauss-Seidel converges.
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

    Returns:
        A new dictionary of options.
    """
    if comm_size <= 1:
        return dict(options)
    return _parallel_variant(name, options)[0]


def parallel_note(name: str, comm_size: int = 2) -> str:
    """What :func:`preset_options` changes in preset ``name`` under MPI ("" if nothing).

    Raises:
        KeyError: with the known names, if ``name`` is not a preset.
    """
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

    Args:
        name: A key of :data:`PRESETS` or :data:`MIXED_ONLY_PRESETS`.
        comm_size: Number of MPI processes.

    Returns:
        A new dictionary of options (names without prefix).

    Raises:
        KeyError: with the known names, if ``name`` is not a preset.
    """
    return parallel_options(name, _lookup(name), comm_size)


def forcing_options(forcing: str, options: Mapping[str, str]) -> dict[str, str]:
    """The options of ``solver.forcing`` for a solver whose merged options are ``options``.

    Args:
        forcing: A key of :data:`FORCING`.
        options: The solver's options without the forcing layer.

    Returns:
        The options to add (none for ``"tight"``).

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

    Args:
        layer: The preset's options.
        above: The options of the higher layers (scene and command line).

    Returns:
        A new dictionary: ``layer`` without the replaced components' options.
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
