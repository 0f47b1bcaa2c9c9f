"""Speed options and their accuracy cost, measured against the exact configuration.

Every option here is off by default and given as PETSc options (command line or scene
``[solver.petsc]``) or scene keys:

* Jacobian lagging ``-snes_lag_jacobian 2 -snes_lag_jacobian_persists``: the Hessian (and,
  for direct presets, its factorisation) is rebuilt every second Newton iteration, across
  steps; Newton still iterates to the residual tolerance, so the cost is iterations;
* preconditioner lagging ``-snes_lag_preconditioner 2``: Krylov presets keep the ICC factor
  of an older Hessian;
* Eisenstat-Walker forcing ``-snes_ksp_ew``: the Krylov tolerance follows the Newton
  residual instead of ``ksp_rtol`` (iterative presets), with PETSc's parameters and with
  the scene's ``solver.forcing = "adaptive"`` (choice 2 capped at 1e-2,
  :data:`fem_anim.solver.presets.FORCING`);
* storage ``-mat_type aij`` against the Krylov presets' default ``baij`` (d x d blocks);
* quadrature reduction ``element.quadrature_degree = 1`` for P2 (default 2).

Accuracy: the tip's mean displacement after the steps, relative deviation from the exact
configuration's (same mesh, same element degree).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_anim.output.products import write_product

__all__ = ["OPTION_CASES", "options_table"]

#: (label, preset, PETSc options, extra scene overrides, baseline label)
OPTION_CASES = (
    ("cholesky (exact)", "cholesky", {}, [], None),
    ("cholesky, lag Jacobian 2", "cholesky",
     {"snes_lag_jacobian": "2", "snes_lag_jacobian_persists": ""}, [], "cholesky (exact)"),
    ("cg-icc (exact, baij)", "cg-icc", {}, [], None),
    ("cg-icc, aij storage", "cg-icc", {"mat_type": "aij"}, [], "cg-icc (exact, baij)"),
    ("cg-icc, Eisenstat-Walker (PETSc defaults)", "cg-icc", {"snes_ksp_ew": ""}, [],
     "cg-icc (exact, baij)"),
    ("cg-icc, solver.forcing = adaptive", "cg-icc", {}, ['solver.forcing="adaptive"'],
     "cg-icc (exact, baij)"),
    ("cg-icc, lag preconditioner 2", "cg-icc",
     {"snes_lag_preconditioner": "2", "snes_lag_preconditioner_persists": ""}, [],
     "cg-icc (exact, baij)"),
    ("cg-jacobi (exact, baij)", "cg-jacobi", {}, [], None),
    ("cg-jacobi, aij storage", "cg-jacobi", {"mat_type": "aij"}, [], "cg-jacobi (exact, baij)"),
    ("P2 cholesky, quadrature 2", "cholesky", {}, ["element.degree=2",
                                                    "mesh.element_size=0.05"], None),
    ("P2 cholesky, quadrature 1", "cholesky", {},
     ["element.degree=2", "mesh.element_size=0.05", "element.quadrature_degree=1"],
     "P2 cholesky, quadrature 2"),
)


def options_table(scene_path, overrides, out: Path, log=print, h: float = 0.025,
                  steps: int = 10) -> str:
    """Run every case in this process; the markdown section (also ``out/options.md``)."""
    from mpi4py import MPI

    from fem_anim.scene.loading import load_scene
    from fem_anim.bench.report import md_table
    from fem_anim.bench.worker import measure

    results, body = {}, []
    for label, preset, petsc, sets, baseline in OPTION_CASES:
        scene = load_scene(scene_path, [*overrides, f"mesh.element_size={h}", *sets])
        r = measure(scene, preset, steps, dict(petsc), MPI.COMM_WORLD, tip=True)
        total = float(sum(s["wall"] for s in r["steps"][1:]))
        its = int(sum(s["newton_its"] for s in r["steps"]))
        lin = int(sum(s["linear_its"] for s in r["steps"]))
        tip = np.asarray(r["tip"])
        results[label] = (total, tip)
        if baseline is None:
            speedup, dev = 1.0, 0.0
        else:
            base_total, base_tip = results[baseline]
            speedup = base_total / total
            dev = float(np.abs(tip - base_tip).max() / np.abs(base_tip).max())
        body.append([label, r["tets"], r["dofs"], its, lin, total / (steps - 1), speedup, dev])
        log(f"  {label}: {total / (steps - 1):.3f} s/step, x{speedup:.2f}, tip dev {dev:.1e}")
    text = ("## Options (off by default)\n\n"
            f"Default beam, mesh.element_size = {h} (P2 rows: 0.05), {steps} steps, Newton to "
            "the default tolerance. 'speed-up' is the exact configuration's time over the "
            "option's (steps 2..n); 'tip dev.' the largest deviation of the tip's mean "
            "displacement from the exact configuration's, relative to its largest value.\n\n"
            + md_table(["configuration", "tets", "dofs", "Newton its", "linear its",
                        "s/step", "speed-up", "tip dev."], body))
    write_product(out / "options.md", (text + "\n").encode())
    return text
