"""Mutation check: plant realistic bugs one at a time and see that the suite catches each.

Each entry of :data:`MUTATIONS` names a file, an exact piece of its text that occurs once,
the text to put in its place (a wrong sign, factor, index or evaluation point), and the
small test selection that must fail because of it. The script copies the repository's
files (tracked and untracked, not ignored: the working state, not a commit) into a
temporary directory outside the repository, checks once that Python really imports
``fem_anim`` from that copy (a sentinel planted in the copy's ``fem_anim/__init__.py``
must break ``import fem_anim``), then for each mutation edits the copy, runs the
selection there with ``PYTHONPATH`` pointing at the copy, and restores the file. The
worktree is never modified.

A mutation is *caught* when its selection fails with the bug planted (and, unless
``--no-baseline``, passes without it). The script prints caught / missed per mutation
and the kill rate, and exits 1 if any mutation is missed (2 for a malformed list).

It is not collected by pytest (its name does not start with ``test_``) and CI does not
run it: a full run takes 4-8 minutes on 2 shared cores. ``tests/test_mutation_list.py``
(fast, in CI) checks that every listed original text still occurs exactly once and that
every selected test exists, so the list cannot rot silently when the code changes.

Usage::

    .venv/bin/python tests/tools/mutation_check.py             # all mutations, with baselines
    .venv/bin/python tests/tools/mutation_check.py --list      # names and selections
    .venv/bin/python tests/tools/mutation_check.py --only friction-pressure-dhat  # one
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

__all__ = ["Mutation", "MUTATIONS", "ROOT", "copy_tree", "main"]


@dataclass(frozen=True)
class Mutation:
    """One planted bug.

    Attributes:
        name: Short identifier (``--only``).
        path: File relative to the repository root.
        original: Exact text replaced; must occur exactly once in the file.
        replacement: The buggy text.
        tests: pytest node ids (``tests/test_x.py::test_y`` or ``...::test_y[param]``)
            of which at least one must fail.
        why: What the bug is, in words.
    """

    name: str
    path: str
    original: str
    replacement: str
    tests: tuple[str, ...]
    why: str


IND = "tests/test_independent_checks.py"
CONTACT = "tests/test_contact.py"
REF = "tests/test_reference_comparison.py"
MODES = "tests/test_hessian_modes.py"
TR_RESET = ("tests/test_trust_region_step_reset.py::"
            "test_a_step_after_a_trust_region_is_a_fresh_minimisers_step")
SCHUR = ("tests/test_schur_preconditioner.py::"
         "test_schur_complement_against_its_preconditioner")
BODY_MOTION = "tests/test_per_body_momentum.py::test_each_body_moves_rigidly_about_its_own_centre"

MUTATIONS: list[Mutation] = [
    # -- six bugs the independent checks were written to catch --------------------------------
    Mutation("friction-pressure-dhat", "forms/obstacle_contact.py",
             "- (d - dhat) ** 2 / d, 0.0)", "- (d - dhat) ** 2 / dhat, 0.0)",
             (f"{IND}::test_friction_matches_reference",),
             "barrier derivative with d_hat where d belongs: friction pressure off by ~7 %"),
    Mutation("sphere-curvature-sign", "fem_anim/contact/obstacles.py",
             'terms.append(-ob["stiffness"] / ob["dhat"] * slope',
             'terms.append(ob["stiffness"] / ob["dhat"] * slope',
             (f"{IND}::test_projected_sphere_hessian_matches_reference",),
             "curvature correction of the sphere barrier's Hessian with the wrong sign"),
    Mutation("filter-wrong-trial", "fem_anim/solver/step_bounds.py",
             "trial.axpy(-1.0, y)", "trial.axpy(1.0, y)",
             (f"{IND}::test_inversion_filter_halves_a_constructed_step",),
             "inversion filter checks x + y instead of the trial point x - y"),
    Mutation("swap-rtol-atol", "fem_anim/solver/presets.py",
             '"snes_rtol": "1e-8",\n    "snes_atol": "1e-12",',
             '"snes_rtol": "1e-12",\n    "snes_atol": "1e-8",',
             (f"{IND}::test_every_accepted_step_meets_the_residual_test",),
             "Newton's default relative and absolute tolerances swapped"),
    Mutation("p2-mass-low-quadrature", "forms/inertia.py",
             'dx(metadata={"quadrature_degree": 2 * degree})',
             'dx(metadata={"quadrature_degree": degree + 1})',
             (f"{IND}::test_consistent_mass_moments_are_exact[2]",),
             "consistent mass integrated below degree 2k: inexact for P2"),
    Mutation("rayleigh-beta-factor", "forms/damping.py",
             "term = coefficient * beta * linear.psi(",
             "term = coefficient * 2.0 * beta * linear.psi(",
             (f"{IND}::test_rayleigh_damping_decays_a_mode_at_the_closed_form_rate",),
             "stiffness-proportional damping twice too strong"),
    # -- forms/ ----------------------------------------------------------------------------------
    Mutation("rayleigh-alpha-half", "forms/damping.py",
             "form = coefficient * alpha * 0.5 * rho", "form = coefficient * alpha * rho",
             (f"{IND}::test_rayleigh_damping_decays_a_mode_at_the_closed_form_rate",),
             "mass-proportional damping twice too strong (1/2 lost)"),
    Mutation("inertia-half", "forms/inertia.py",
             "return 0.5 * rho * ufl.inner(w, w) * dx_mass",
             "return rho * ufl.inner(w, w) * dx_mass",
             (f"{REF}::test_step_objective[3-neohookean]",
              "tests/test_constant_terms.py::test_constant_terms_equal_the_single_form"),
             "inertia term 1/2 ||x - y||_M^2 without its 1/2 (since the constant terms its value "
             "comes from M; the form still makes the damped constant Hessian and y^T H y)"),
    Mutation("kinetic-half", "forms/inertia.py",
             "return 0.5 * rho * ufl.inner(v, v) * dx_mass",
             "return rho * ufl.inner(v, v) * dx_mass",
             (f"{IND}::test_consistent_mass_moments_are_exact[1]",),
             "kinetic energy without its 1/2"),
    Mutation("neohookean-sign", "forms/neohookean.py",
             "- mu * lnJ + lmbda / 2 * lnJ**2", "+ mu * lnJ + lmbda / 2 * lnJ**2",
             (f"{REF}::test_elastic_energy_gradient_hessian[3-neohookean-perturbed]",),
             "neo-Hookean -mu ln J with the wrong sign (stress at rest)"),
    Mutation("stvk-lambda-factor", "forms/stvk.py",
             "lmbda / 2 * ufl.tr(E) ** 2", "lmbda * ufl.tr(E) ** 2",
             (f"{REF}::test_elastic_energy_gradient_hessian[3-stvk-perturbed]",),
             "StVK volumetric term twice too stiff"),
    Mutation("lame-mu", "forms/lame.py",
             "mu = E / (2 * (1 + nu))", "mu = E / (2 * (1 - nu))",
             ("tests/test_forms_materials.py::test_lame_parameters",),
             "shear modulus with 1 - nu"),
    Mutation("gravity-sign", "forms/gravity.py",
             "return -rho * ufl.inner(g, u) * dx", "return rho * ufl.inner(g, u) * dx",
             ("tests/test_integrators.py::test_newmark_free_fall_is_exact[consistent]",),
             "gravity pushes up"),
    Mutation("friction-tangent-sign", "forms/obstacle_contact.py",
             "u_T = du - ufl.dot(normal_n, du) * normal_n",
             "u_T = du + ufl.dot(normal_n, du) * normal_n",
             (f"{IND}::test_friction_matches_reference",),
             "friction's tangential projection with the wrong sign"),
    Mutation("friction-smoothing", "forms/obstacle_contact.py",
             "+ y2 / eps\n", "+ y2 / (2.0 * eps)\n",
             (f"{IND}::test_friction_matches_reference",),
             "f0's quadratic term halved: f0 no longer C^1 at eps"),
    # -- fem_anim/ physics -----------------------------------------------------------------------
    Mutation("friction-lag-point", "fem_anim/contact/obstacles.py",
             "x_n = self.X + u_prev", "x_n = self.X + u",
             (f"{IND}::test_friction_matches_reference",),
             "friction pressure and normal taken at the current, not the lagged, point"),
    Mutation("vertex-rule-weight", "fem_anim/contact/obstacles.py",
             "weights = np.full(tdim, 1.0 / math.factorial(tdim - 1) / tdim)",
             "weights = np.full(tdim, 1.0 / tdim)",
             (f"{CONTACT}::test_barrier_matches_reference[plane-3]",),
             "vertex rule without the reference facet's area 1/(d-1)!"),
    Mutation("friction-mu-half", "fem_anim/contact/obstacles.py",
             'PETSc.ScalarType(ob["friction"]))', 'PETSc.ScalarType(0.5 * ob["friction"]))',
             (f"{CONTACT}::test_block_on_tilted_plane_sticks_or_slides[0.6-False]",),
             "friction coefficient halved: a block that must stick slides"),
    Mutation("keep-fraction", "fem_anim/contact/obstacles.py",
             "keep = (1.0 - KEEP_FRACTION) * d0", "keep = KEEP_FRACTION * d0",
             (f"{CONTACT}::test_step_bound_stops_at_keep_fraction",),
             "step bound keeps the wrong fraction of the distance"),
    Mutation("sphere-bound-root", "fem_anim/contact/obstacles.py",
             "root = c0[hit] / (ab[hit] + np.sqrt(disc[hit]))",
             "root = c0[hit] / (ab[hit] - np.sqrt(disc[hit]))",
             (f"{CONTACT}::test_step_bound_stops_at_keep_fraction",),
             "sphere step bound takes the far root of the quadratic"),
    Mutation("newmark-predictor", "fem_anim/simulation/integrators.py",
             "0.25 * h * h * state.a  # seed eq. 3", "0.5 * h * h * state.a  # seed eq. 3",
             ("tests/test_integrators.py::test_newmark_free_fall_is_exact[consistent]",),
             "Newmark predictor with h^2/2 a_n"),
    Mutation("newmark-velocity", "fem_anim/simulation/integrators.py",
             "v_new = state.v + 0.5 * h * (state.a + a_new)", "v_new = state.v + h * a_new",
             ("tests/test_integrators.py::test_newmark_free_fall_is_exact[consistent]",),
             "Newmark velocity update with the end-point acceleration only"),
    Mutation("newmark-damping-anchor", "fem_anim/simulation/integrators.py",
             "return w / (0.5 * h), state.u + 0.5 * h * state.v",
             "return w / h, state.u + 0.5 * h * state.v",
             (f"{IND}::test_rayleigh_damping_decays_a_mode_at_the_closed_form_rate",),
             "Newmark damping potential with tau = h instead of h/2"),
    Mutation("bdf2-predictor", "fem_anim/simulation/integrators.py",
             "h * (8.0 * state.v - 2.0 * state.v_old) / 9.0",
             "h * (8.0 * state.v + 2.0 * state.v_old) / 9.0",
             ("tests/test_integrators.py::test_order_of_accuracy_linear[bdf2]",),
             "BDF2 predictor with the wrong sign of v_{n-1}"),
    # -- solver ----------------------------------------------------------------------------------
    Mutation("polish-always-converged", "fem_anim/solver/stopping.py",
             "return POLISH_FAILED_REASON, norm", "return ROUNDOFF_REASON, norm",
             (f"{IND}::test_polish_meets_the_test_or_reports_it",),
             "a polish that missed the residual test reported as converged"),
    Mutation("relative-test-loose", "fem_anim/solver/stopping.py",
             "elif fnorm <= rtol * self.history[0][0]:",
             "elif fnorm <= rtol * self.history[0][0] * 1e6:",
             (f"{IND}::test_every_accepted_step_meets_the_residual_test",),
             "relative residual test a million times too loose"),
    Mutation("filter-threshold", "fem_anim/solver/step_bounds.py",
             "if problem.min_det_F() > 0.0:", "if problem.min_det_F() > -1.0:",
             (f"{IND}::test_inversion_filter_halves_a_constructed_step",),
             "inversion filter accepts det F > -1 (inverted elements)"),
    Mutation("contact-points-swapped", "fem_anim/contact/obstacles.py",
             "return values[:, 0], values[:, 1]", "return values[:, 1], values[:, 0]",
             (f"{CONTACT}::test_step_bound_stops_at_keep_fraction[plane]",),
             "contact points and search directions read from the wrong columns"),
    Mutation("newmark-weight", "forms/time_schemes.py",
             'Scheme("newmark", 2, 0.25)', 'Scheme("newmark", 2, 0.5)',
             ("tests/test_integrators.py::test_newmark_free_fall_is_exact[consistent]",),
             "Newmark's energy weight h^2/2 instead of h^2/4"),
    Mutation("contact-energy-scale", "forms/obstacle_contact.py",
             "return kappa / dhat * barrier(d, dhat) * ds", "return kappa * barrier(d, dhat) * ds",
             (f"{CONTACT}::test_barrier_matches_reference[plane-3]",),
             "contact energy without its 1/d_hat (kappa no longer a pressure)"),
    Mutation("bdf2-velocity", "fem_anim/simulation/integrators.py",
             "v_new = 1.5 / h * (u_new", "v_new = 1.0 / h * (u_new",
             ("tests/test_integrators.py::test_order_of_accuracy_linear[bdf2]",),
             "BDF2 velocity update with 1/h instead of 3/(2h)"),
    # -- the numpy reference (an oracle with a bug must be caught too) ---------------------------
    Mutation("reference-barrier-curvature", "fem_anim/reference/obstacle_barrier.py",
             "+ t ** 2 / a ** 2", "- t ** 2 / a ** 2",
             (f"{CONTACT}::test_reference_derivatives_by_finite_differences[plane]",),
             "reference barrier b'' with a wrong sign"),
    Mutation("reference-friction-eps", "fem_anim/reference/obstacle_barrier.py",
             "return -y ** 3 / (3.0 * eps ** 2) + y ** 2 / eps + eps / 3.0",
             "return -y ** 3 / (3.0 * eps ** 2) + y ** 2 / eps + eps / 2.0",
             (f"{IND}::test_reference_friction_gradient_by_finite_differences",),
             "reference f0 discontinuous at eps"),
    # -- extremes: expectations derived from the scene ---------------------------------------
    Mutation("extremes-pin-sign", "fem_anim/bench/extreme_cases.py",
             "    return v * (t if until is None else min(t, until))",
             "    return -v * (t if until is None else min(t, until))",
             ("tests/test_extremes.py::test_expected_outcomes_follow_from_the_scene[2D]",),
             "pin displacement with the wrong sign: the press opens the gap it closes, so the "
             "crushed bar would be expected to finish"),
    Mutation("extremes-stroke-compare", "fem_anim/bench/extreme_cases.py",
             'g["first_closing"] >= case.keys["mesh"]["element_size"]',
             'g["first_closing"] <= case.keys["mesh"]["element_size"]',
             ("tests/test_extremes.py::test_expected_outcomes_follow_from_the_scene[2D]",),
             "a first-step stroke compared the wrong way: every gentle pin motion is "
             "expected to need substeps"),
    # -- budget, preview, parallel residual ------------------------------------------------------
    Mutation("budget-accepts-worse", "fem_anim/solver/stopping.py",
             "better, shown = g < g0,", "better, shown = True,",
             ("tests/test_budget.py::test_accept_keeps_only_an_iterate_that_lowered_g",),
             "on_budget = accept keeps an iterate that raised the step objective"),
    Mutation("preview-overrides-explicit", "fem_anim/scene/modes.py",
             "solver.setdefault(key, value)", "solver[key] = value",
             ("tests/test_preview.py::test_explicit_keys_win_over_the_preview",),
             "the preview overwrites the solver keys the scene gave"),
    Mutation("lifting-stale-ghosts", "fem_anim/problem/objective.py",
             "[compat.petsc_vec(self.unknown)], -1.0)", "[x], -1.0)",
             ("tests/test_mpi_gradient.py::test_residual_is_the_objectives_gradient_under_mpi",
              "tests/test_constant_terms.py::test_constant_terms_under_mpi"),
             "the lifting reads SNES's iterate at ghost dofs (stale under MPI; the lifting runs "
             "only with pins off their values, which the second test sets)"),
    Mutation("truncated-cg-indefinite-pc", "fem_anim/solver/trust_region.py",
             "wanted = self._pc_matrix if filtered else A", "wanted = A",
             ("tests/test_hessian_modes.py::"
              "test_auto_with_cg_preconditions_by_a_positive_definite_matrix",),
             "auto with CG keeps ICC(0) of the indefinite Hessian as its preconditioner"),
    Mutation("trust-radius-unset", "fem_anim/solver/trust_region.py",
             "set_radius(ksp, self._radius)",
             "set_radius(ksp, 0.0)",
             ("tests/test_hessian_modes.py::test_auto_with_cg_steps_in_a_trust_region",),
             "KSPSTCG runs without a radius (unconstrained, as plain CG)"),
    Mutation("trust-model-curvature-sign", "fem_anim/solver/trust_region.py",
             "model_value(ksp) + slope / t)", "model_value(ksp) - slope / t)",
             ("tests/test_hessian_modes.py::test_auto_with_cg_steps_in_a_trust_region",),
             "y^T A y from KSPSTCG's model value with the linear term's sign flipped"),
    Mutation("trust-radius-no-shrink", "fem_anim/solver/hessian_modification.py",
             "    if rho < 0.25:\n        return 0.25 * taken",
             "    if rho < 0.25:\n        return radius",
             ("tests/test_ksp_trust_region.py::test_trust_radius_rule",),
             "a poor model keeps the trust radius"),
    Mutation("aij-preconditioner-stale", "fem_anim/solver/trust_region.py",
             "        if filtered:\n            A.convert(",
             "        if filtered and self.aij_preconditioners == 0:\n            A.convert(",
             ("tests/test_hessian_modes.py::"
              "test_auto_with_cg_preconditions_by_a_positive_definite_matrix",),
             "the AIJ copy of A that preconditions CG is made once and never refreshed"),
    Mutation("abs-into-converted-matrix", "fem_anim/solver/trust_region.py",
             "self.problem.jacobian(snes, x, self._abs_matrix, self._abs_matrix)",
             "self.problem.jacobian(snes, x, self._aij_matrix(), self._aij_matrix())",
             ("tests/test_hessian_modes.py::test_trust_region_under_mpi",),
             "the abs-filtered Hessian assembled into the MatConvert target (new nonzeros: a "
             "PETSc error on 2 ranks)"),
    Mutation("first-radius-literal", "fem_anim/solver/trust_region.py",
             "else self._jacobi_length(A)", "else 1.0",
             (f"{MODES}::test_a_trust_region_without_a_newton_direction_starts_at_the_"
              "jacobi_step",),
             "the first trust radius of a step without a Newton direction a fixed 1 m"),
    Mutation("polish-steps-uncounted", "fem_anim/solver/minimiser.py",
             "            newton_its += self.stop.polish_its  # the polish",
             "            newton_its += 0 * self.stop.polish_its  # the polish",
             (f"{MODES}::test_every_newton_iteration_is_counted_under_its_hessian",),
             "the round-off polish's full Newton steps left out of newton_its"),
    Mutation("dropped-direction-uncounted", "fem_anim/solver/minimiser.py",
             "getIterationNumber() + (reason in FAILED_DIRECTION)",
             "getIterationNumber() + 0 * (reason in FAILED_DIRECTION)",
             (f"{MODES}::test_a_direction_whose_solve_failed_is_counted",),
             "a direction whose line search failed left out of newton_its (PETSc's count)"),
    Mutation("users-stcg-switched-to-cg", "fem_anim/solver/trust_region.py",
             "        if self._in_region:\n            self.snes.getKSP().setType(\"cg\")",
             "        if True:\n            self.snes.getKSP().setType(\"cg\")",
             ("tests/test_hessian_modes.py::test_a_users_own_stcg_is_left_alone",),
             "every step start makes the KSP CG, the user's -ksp_type stcg included"),
    Mutation("cg-ascent-direction-kept", "fem_anim/solver/trust_region.py",
             "or r.dot(y) > 0.0:", "or r.dot(y) > -1e300:",
             ("tests/test_hessian_modes.py::test_auto_with_cg_replaces_an_ascent_direction",),
             "auto with CG keeps PETSc's ascent direction after negative curvature at once"),
    Mutation("jit-lock-left-on-exception", "fem_anim/compat.py",
             "    except BaseException:\n        for lock in",
             "    except BaseException as err:\n        if isinstance(err, Exception):\n"
             "            raise\n        for lock in",
             ("tests/test_safety.py::"
              "test_an_interruption_between_ffcx_lock_and_compile_leaves_no_lock",),
             "a signal's Interrupted between FFCx's lock and its try leaves the lock"),
    Mutation("damping-beta-ignored", "fem_anim/scene/loading.py",
             'and (damping["alpha"] > 0 or damping["beta"] > 0)', 'and damping["alpha"] > 0',
             ("tests/test_cli.py::test_default_scene_outputs",),
             "stiffness-proportional damping alone builds no term (the default scene undamped)"),
    Mutation("constant-terms-no-lifting", "fem_anim/problem/constant_terms.py",
             "            fem_petsc.set_bc(z, self.bcs)  # x~", "            pass  # x~",
             ("tests/test_constant_terms.py::test_constant_terms_equal_the_single_form",),
             "the inertia gradient taken at x, not with the pins at their prescribed values"),
    Mutation("constant-hessian-stale", "fem_anim/problem/constant_terms.py",
             "        if assembled_for != scales:", "        if assembled_for is None:",
             ("tests/test_constant_terms.py::test_constant_terms_equal_the_single_form",),
             "the damping Hessian kept at its first coefficient when dt changes"),
    Mutation("lifting-always-skipped", "fem_anim/problem/objective.py",
             "        if not self._pins_on_target():", "        if False:",
             ("tests/test_constant_terms.py::test_constant_terms_equal_the_single_form",),
             "the residual's lifting skipped although the pins are off their values"),
    Mutation("pins-not-owners-choice", "fem_anim/problem/pins.py",
             "            dofs = self._owners_choice(dofs)\n", "",
             ("tests/test_constant_terms.py::test_constant_terms_under_mpi",),
             "each rank pins the vertices its own dof coordinates put in the box (a vertex on "
             "the box's face: pinned as a ghost, free on its owner)"),
    Mutation("inertia-value-anchor-sign", "fem_anim/problem/constant_terms.py",
             "            z.axpy(-1.0, compat.petsc_vec(term.anchor))\n            Q.mult(z, Qz)\n"
             "            total",
             "            z.axpy(1.0, compat.petsc_vec(term.anchor))\n            Q.mult(z, Qz)\n"
             "            total",
             ("tests/test_reference_comparison.py::test_step_objective",),
             "the inertia term's value taken at x + y instead of x - y"),
    # -- every command keeps run's promise: its own files only, one line, nothing half-made ------
    Mutation("lock-keeps-stale-digits", "fem_anim/output/rundir.py",
             "    os.ftruncate(fd, 0)\n", "",
             ("tests/test_command_safety.py::test_lock_holds_exactly_the_current_pid",),
             "the lock file rewritten in place: a shorter pid keeps the old one's last digits"),
    Mutation("foreign-files-none", "fem_anim/output/rundir.py",
             "and ((path / name).exists() or (path / name).is_symlink())]",
             "and (path / name).is_symlink()]",
             ("tests/test_command_safety.py::"
              "test_render_refuses_a_users_folder_holding_a_trajectory",
              "tests/test_command_safety.py::"
              "test_trade_study_refuses_a_users_file_before_measuring"),
             "a user's file of a product's name not seen: render and bench write over it"),
    Mutation("manifest-not-consulted", "fem_anim/output/rundir.py",
             "    return [name for name in sorted(set(names)) if name not in owned\n",
             "    return [name for name in sorted(set(names)) if owned is not None\n",
             ("tests/test_command_safety.py::"
              "test_render_into_a_users_folder_writes_only_its_own_names",),
             "fem_anim's own files (in the manifest) refused too: a second rendering fails"),
    Mutation("install-unchecked", "fem_anim/output/rundir.py",
             "    if foreign:  # checked before anything moves", "    if False:  # checked",
             ("tests/test_command_safety.py::test_install_refuses_to_replace_an_unlisted_file",),
             "install renames over a file the manifest does not list (a user's)"),
    Mutation("staging-kept-on-error", "fem_anim/output/products.py",
             "    finally:\n        shutil.rmtree(staging, ignore_errors=True)",
             "    except BaseException:\n        raise",
             ("tests/test_command_safety.py::test_staged_products_leave_nothing_when_a_write_fails",
              "tests/test_command_safety.py::test_signal_while_rendering_leaves_the_old_pictures"),
             "a failed or interrupted write leaves its half-made staging folder behind"),
    Mutation("render-os-error-traceback", "fem_anim/render/process.py",
             "    except OSError as err:  # read-only or full file system",
             "    except ZeroDivisionError as err:  # read-only or full file system",
             ("tests/test_command_safety.py::test_render_on_a_read_only_file_system_is_one_line",),
             "an OS error in the render process is a traceback and exit 1"),
    Mutation("render-ffmpeg-line-taken", "fem_anim/render/process.py",
             'last = message.splitlines()[-1] if message else ""',
             'last = message.splitlines()[0] if message else ""',
             ("tests/test_command_safety.py::"
              "test_render_on_a_full_disk_is_one_line_and_installs_nothing",
              "tests/test_command_safety.py::"
              "test_the_renderers_own_error_line_is_taken_after_ffmpegs"),
             "the renderer's error read from its first stderr line (ffmpeg's), not its own"),
    Mutation("trade-checks-after-the-study", "fem_anim/bench/trade.py",
             "            check_may_write(out, PRODUCTS)\n", "",
             ("tests/test_command_safety.py::"
              "test_trade_study_refuses_a_users_file_before_measuring",),
             "a user's trade_study.md found only after the whole study has run"),
    Mutation("trade-writes-in-place", "fem_anim/bench/trade.py",
             "                _write_outputs(staging, study,",
             "                _write_outputs(out, study,",
             ("tests/test_command_safety.py::"
              "test_trade_study_writes_beside_users_files_and_replaces_its_own",),
             "the study's files written in place: a full disk leaves a half-replaced study"),
    Mutation("perf-checks-after-the-sweep", "fem_anim/bench/perf.py",
             "        check_may_write(out, [*report.PRODUCTS, *sections])", "        pass",
             ("tests/test_command_safety.py::"
              "test_perf_bench_refuses_a_users_file_before_the_sweep",),
             "a user's perf.md found only after hours of measurements"),
    Mutation("extremes-overwrites", "fem_anim/bench/extremes.py",
             "            check_may_write(Path(args.output).parent, [Path(args.output).name],\n"
             "                            MPI.COMM_WORLD)",
             "            pass",
             ("tests/test_command_safety.py::test_extremes_refuses_a_users_file_before_the_cases",),
             "bench --extremes -o FILE runs every case before it finds the user's FILE"),
    Mutation("render-sigterm-no-cleanup", "fem_anim/render/process.py",
             "STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)",
             "STOP_SIGNALS = (signal.SIGINT,)",
             ("tests/test_command_safety.py::"
              "test_signal_while_rendering_leaves_the_old_pictures",),
             "a renderer stopped by SIGTERM leaves its staged frames behind"),
    Mutation("bench-peers-checks-after", "fem_anim/bench/peers.py",
             '        check_may_write(out, ["peers.md"])  # before the runs, not after\n', "",
             ("tests/test_command_safety.py::"
              "test_other_benches_refuse_a_users_file_before_measuring",),
             "python -m fem_anim.bench.peers finds the user's peers.md only after its runs"),
    # -- contracts checked independently: placement, per-body motion, energy report, lock,
    #    intersection check, solver modes on [[body]] scenes, the trust region's per-step state
    Mutation("body-rotation-order", "fem_anim/mesh/bodies.py",
             "return Rz @ Ry @ Rx", "return Rx @ Ry @ Rz",
             ("tests/test_body_placement.py::test_rotation_matrix_is_scipys_extrinsic_xyz",),
             "the body turned about z first, then y, then x (same for one axis alone)"),
    Mutation("body-ry-sign", "fem_anim/mesh/bodies.py",
             "Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])",
             "Ry = np.array([[cy, 0, -sy], [0, 1, 0], [sy, 0, cy]])",
             ("tests/test_body_placement.py::test_rotation_matrix_is_scipys_extrinsic_xyz",),
             "the rotation about y turned the wrong way"),
    Mutation("body-placement-untransposed", "fem_anim/mesh/bodies.py",
             'points @ rotation_matrix(body["rotation"], d).T + offset',
             'points @ rotation_matrix(body["rotation"], d) + offset',
             ("tests/test_body_placement.py::test_placed_vertices_of_a_turned_body",),
             "the placed vertices turned by R^T (the inverse rotation) instead of R"),
    Mutation("initial-centre-of-the-scene", "fem_anim/simulation/initial_state.py",
             "center = center_of_mass(problem, body) if",
             "center = center_of_mass(problem) if",
             (BODY_MOTION,),
             "a body spins about the whole scene's centre of mass instead of its own"),
    Mutation("initial-omega-cross-order", "fem_anim/simulation/initial_state.py",
             "return v + np.cross(np.asarray(omega, dtype=float), r)",
             "return v + np.cross(r, np.asarray(omega, dtype=float))",
             (BODY_MOTION,),
             "r x omega for omega x r: the body spins backwards (same kinetic energy)"),
    Mutation("initial-first-body-dofs", "fem_anim/simulation/initial_state.py",
             "cells = np.flatnonzero(problem.cell_body == body).astype(np.int32)",
             "cells = np.flatnonzero(problem.cell_body == 0).astype(np.int32)",
             (BODY_MOTION,),
             "every body's initial velocity written onto the first body's dofs"),
    Mutation("report-gain-conservative-only", "fem_anim/simulation/energy_report.py",
             "gained = not moving and drift", "gained = conservative and drift",
             ("tests/test_energy_report_classes.py::"
              "test_a_gain_is_flagged_for_every_scene_without_moving_pins",),
             "an energy gain of a damped or frictional scene left unflagged"),
    Mutation("report-loss-flagged-when-damped", "fem_anim/simulation/energy_report.py",
             "damped = conservative and drift is not None",
             "damped = not moving and drift is not None",
             ("tests/test_energy_report_classes.py::"
              "test_a_loss_is_flagged_only_for_a_conservative_scene",),
             "the loss of a damped or frictional scene flagged as numerical damping"),
    Mutation("report-turning-pin-still", "fem_anim/simulation/energy_report.py",
             'return any(p["velocity"] is not None or p["angular_velocity"] != 0',
             'return any(p["velocity"] is not None and p["angular_velocity"] != 0',
             ("tests/test_energy_report_classes.py::test_a_turning_handle_is_a_moving_pin",),
             "a handle that only turns counted as a still pin: its work flagged as a gain"),
    Mutation("lock-stale-tail-kept", "fem_anim/output/rundir.py",
             "os.ftruncate(fd, 0)", "os.lseek(fd, 0, os.SEEK_SET)",
             ("tests/test_lock_file.py::test_a_stale_lock_of_a_longer_pid_is_replaced_by_ours",),
             "the lock file not truncated: a shorter pid leaves the stale pid's tail"),
    Mutation("intersection-rest-positions", "fem_anim/contact/intersection.py",
             "ipctk.has_intersections(mesh, np.asfortranarray(rest + u[used]))",
             "ipctk.has_intersections(mesh, np.asfortranarray(rest))",
             ("tests/test_intersection_check.py::"
              "test_a_planted_crossing_is_found_and_only_there",),
             "the check looks at the rest positions, not the frame's: never a crossing"),
    Mutation("intersection-interior-faces", "fem_anim/contact/intersection.py",
             "unique[counts == 1]", "unique[counts >= 1]",
             ("tests/test_intersection_check.py::test_the_surface_of_a_cube_of_six_tetrahedra",),
             "faces shared by two tetrahedra taken as surface"),
    Mutation("modes-bodies-ignored", "fem_anim/scene/modes.py",
             'bodies = raw.get("body") if isinstance(raw.get("body"), list) else [raw]',
             "bodies = [raw]",
             ("tests/test_solver_modes_bodies.py::"
              "test_bodies_of_several_models_keep_the_exact_hessian",),
             "preview reads the material model of the top level only: on [[body]] scenes of "
             "several models auto filters one model's tangent for all"),
    Mutation("trust-radius-carried-over", "fem_anim/solver/hessian_choice.py",
             "        self._radius = None\n        self._longest = 0.0\n",
             "        self._longest = 0.0\n",
             (TR_RESET,),
             "the trust radius of one step's end carried into the next step"),
    Mutation("cg-indefinite-carried-over", "fem_anim/solver/hessian_choice.py",
             "        self._indefinite_seen = False\n        self.leave_trust_region()\n",
             "        self.leave_trust_region()\n",
             (TR_RESET,),
             "CG's indefiniteness of one step remembered in the next: the next step "
             "preconditioned by the shifted ICC copy and stepped in a trust region at once"),
    Mutation("schur-preconditioner-sign", "fem_anim/problem/mixed_space.py",
             "self.matrix.scale(-weight * self.scale)", "self.matrix.scale(weight * self.scale)",
             (SCHUR,),
             "the Schur preconditioner of the wrong sign (FGMRES still converges, slower)"),
    Mutation("schur-preconditioner-stale", "fem_anim/problem/mixed_space.py",
             "        self.mass.copy(self.matrix)\n", "",
             (SCHUR,),
             "each update rescales the last step's preconditioner instead of the pressure mass"),
    Mutation("schur-preconditioner-no-mu", "fem_anim/problem/objective.py",
             "mu_value * (1.0 + mu_value * inv_kappa))", "(1.0 + mu_value * inv_kappa))",
             (SCHUR,),
             "the Schur preconditioner's scale without the shear modulus"),
    Mutation("mixed-quadrature-one-low", "fem_anim/problem/discretisation.py",
             "max(self.quadrature_degree, 1 + d * (degree - 1))",
             "max(self.quadrature_degree, d * (degree - 1))",
             ("tests/test_quadrature_exactness.py::"
              "test_constraint_of_every_pressure_test_function_is_exact",),
             "the mixed rule one degree low: exact for q = 1 (the volume), not for other q"),
    Mutation("reported-obstacle-energy-with-friction", "fem_anim/problem/energy_terms.py",
             'ufl_forms["contact"] = self.contact.energy',
             'ufl_forms["contact"] = self.contact.energy + self.contact.friction',
             ("tests/test_contact_energy_report.py::"
              "test_reported_contact_energy_is_the_barrier_of_the_written_positions",),
             "the obstacles' lagged friction potential reported as stored contact energy"),
    Mutation("reported-ipc-energy-with-friction", "fem_anim/problem/reported_energies.py",
             'values["contact"] += self.ipc.energy(friction=False)',
             'values["contact"] += self.ipc.energy(friction=True)',
             ("tests/test_contact_energy_report.py::"
              "test_reported_ipc_energy_is_ipctks_barrier_of_the_written_positions",),
             "the lagged friction potential between bodies reported as stored contact energy"),
    # export: USD stages and mesh sequences of a run, body ids (fem_anim/export/)
    Mutation("export-winding-not-flipped", "fem_anim/export/boundary.py",
             "    faces[inward] = faces[inward][:, [0, 2, 1]]\n", "",
             ("tests/test_export.py::test_boundary_of_a_cube_is_closed_and_outward",
              "tests/test_export.py::test_each_body_surface_encloses_its_volume"),
             "boundary faces kept in their cell's order, half of them wound inward"),
    Mutation("export-time-code-shifted", "fem_anim/export/usd_stage.py",
             "    codes = start_frame + np.asarray(times) * frame_rate(times)",
             "    codes = start_frame + 1 + np.asarray(times) * frame_rate(times)",
             ("tests/test_export.py::test_usd_time_samples_are_the_trajectory",),
             "frame k written at time code start + k + 1"),
    Mutation("export-rest-points", "fem_anim/export/usd_stage.py",
             "        x = rest + u\n", "        x = rest + 0.0 * u\n",
             ("tests/test_export.py::test_usd_time_samples_are_the_trajectory",),
             "every time sample the rest shape"),
    Mutation("export-left-handed", "fem_anim/export/usd_stage.py",
             "        mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)\n"
             "        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)\n        primvars",
             "        mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)\n"
             "        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)\n        primvars",
             ("tests/test_export.py::test_usd_validates_and_has_one_prim_per_body",),
             "outward-wound triangles declared left-handed: every face seen inside out"),
    Mutation("export-energy-wrong-faces", "fem_anim/export/usd_stage.py",
             "psi[surface.owner].astype", "psi[:surface.owner.size].astype",
             ("tests/test_export.py::test_energy_density_primvar_is_the_cells_behind_the_faces",),
             "the face's energy density taken from the first cells, not the cell behind it"),
    Mutation("xdmf-body-missing", "fem_anim/output/trajectory.py",
             "            f'<Attribute Name=\"body\" AttributeType=",
             "            f'<Attribute Name=\"bodies\" AttributeType=",
             ("tests/test_export.py::test_body_ids_in_xdmf_vtu_and_usd",),
             "the cells' body number not under the name ParaView users select by"),
    Mutation("export-overwrites-users-file", "fem_anim/export/export_command.py",
             "    if target.exists() and (not owned or target.name not in read_manifest(folder)):",
             "    if False:",
             ("tests/test_export.py::test_export_never_overwrites_a_users_file",),
             "-o onto a user's USD file replaces it"),
    Mutation("sequence-old-frames-kept", "fem_anim/export/export_command.py",
             "        install(staging, root, replaces=older)", "        install(staging, root)",
             ("tests/test_export.py::test_a_shorter_sequence_replaces_the_older_frames_only",),
             "a new sequence leaves the frames of an older one beside it"),
    Mutation("obj-zero-based", "fem_anim/export/mesh_sequence.py",
             "(triangles + 1).tolist()", "triangles.tolist()",
             ("tests/test_export.py::test_mesh_sequences_read_back_with_meshio[obj]",),
             "OBJ face indices written 0-based"),
    # -- gradients through the simulation (fem_anim/adjoint) ------------------------------
    Mutation("adjoint-predictor-sign", "fem_anim/adjoint/backward.py",
             '            y_bar = y_bar - self.vector("y")',
             '            y_bar = y_bar + self.vector("y")',
             ("tests/test_adjoint.py::test_gradient_equals_central_differences",),
             "the predictor's adjoint takes +R_y^T lambda: the cross-step term's sign"),
    Mutation("adjoint-no-damping-anchor", "fem_anim/adjoint/backward.py",
             '                    total = total + maps["D"][k] * d_bar',
             '                    total = total',
             ("tests/test_adjoint.py::test_gradient_equals_central_differences",),
             "the damping anchor's dependence on the previous state left out"),
    Mutation("adjoint-dlambda-dnu", "fem_anim/adjoint/parameters.py",
             "E * (1.0 + 2.0 * nu * nu)", "E * (1.0 + nu * nu)",
             ("tests/test_adjoint.py::test_taylor_remainders_fall_at_orders_one_and_two",),
             "a wrong chain-rule factor dlambda/dnu"),
    Mutation("adjoint-stale-gravity", "fem_anim/problem/constant_terms.py",
             "        if gradient_form is not None:\n            with self.gradient",
             "        if False:\n            with self.gradient",
             ("tests/test_adjoint.py::test_gradient_equals_central_differences",),
             "the forward keeps gravity's nodal force of the first density"),
    Mutation("adjoint-no-initial-acceleration", "fem_anim/adjoint/backward.py",
             '            bar0 = {"u": bar0["u"] + u_part, "v": bar0["v"] + v_part}',
             '            bar0 = {"u": bar0["u"] + u_part, "v": bar0["v"] + 0.0 * v_part}',
             ("tests/test_adjoint.py::test_gradient_equals_central_differences",),
             "Newmark's a_0 = M^-1 (f - C v_0) taken as independent of v_0"),
    Mutation("adjoint-vector-no-ghost-sum", "fem_anim/adjoint/backward.py",
             "        fem_petsc.assemble_vector(vec, self.forms[name])\n"
             "        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)\n",
             "        fem_petsc.assemble_vector(vec, self.forms[name])\n",
             ("tests/test_adjoint.py::test_two_ranks_give_the_serial_gradient",),
             "the adjoint's vectors miss the ghost cells' contributions under MPI"),
    Mutation("adjoint-trajectory-vertex-order", "fem_anim/adjoint/objectives.py",
             "            r = u[self.dofs] - ref[self.index]",
             "            r = u[self.dofs] - ref[self.dofs]",
             ("tests/test_adjoint.py::test_trajectory_of_a_reference_run",),
             "the reference run's vertices matched in dof order, not in input order"),
    Mutation("adjoint-centre-of-mass-gradient", "fem_anim/adjoint/objectives.py",
             "            du = (self.weight * r / self.total * self.m).reshape(-1)",
             "            du = (self.weight * r * self.m).reshape(-1)",
             ("tests/test_adjoint.py::test_gradient_equals_central_differences",),
             "the centre of mass's derivative not divided by the total mass"),
    Mutation("adjoint-ipc-hessian-dropped", "fem_anim/adjoint/backward.py",
             "            ipc.add_hessian(self.H, float(self.problem.weight.value))\n",
             "            pass\n",
             ("tests/test_adjoint_contact.py::test_contact_gradient_equals_central_differences",),
             "the adjoint solves with the step Hessian without IPC's barrier"),
    Mutation("adjoint-ipc-hessian-projected", "fem_anim/adjoint/backward.py",
             "            ipc.exact_hessian(True)\n", "            ipc.exact_hessian(False)\n",
             ("tests/test_adjoint_contact.py::test_contact_gradient_equals_central_differences",),
             "the adjoint solves with IPC's per-pair PSD projection, not the exact Hessian"),
    Mutation("adjoint-ipc-friction-lag-dropped", "fem_anim/contact/lagged_friction.py",
             "        return Hd @ lam + Jl.T @ lam", "        return Hd @ lam",
             ("tests/test_adjoint_contact.py::test_contact_gradient_equals_central_differences"
              "[ipc_friction-implicit_euler]",),
             "IPC friction's normal forces and tangent bases lagged at x_n held fixed"),
    Mutation("adjoint-obstacle-friction-lag-dropped", "fem_anim/adjoint/backward.py",
             '            target["u"] = target["u"] - self.vector("prev")',
             '            target["u"] = target["u"]',
             ("tests/test_adjoint_contact.py::test_contact_gradient_equals_central_differences",),
             "obstacle friction's dependence on u_n (slip, lagged pressure and normal) dropped"),
    Mutation("adjoint-contact-step-test", "fem_anim/adjoint/differentiate.py",
             '    data["solver"]["stopping"] = "norm"\n', '    return scene\n',
             ("tests/test_adjoint_contact.py::test_contact_gradient_equals_central_differences",),
             "the adjoint's forward stops contact steps at IPC's step test (not converged)"),
    Mutation("adjoint-region-cells-ignored", "fem_anim/adjoint/parameters.py",
             "        return np.ones(owned.size, bool) if group is None else owned == group",
             "        return np.ones(owned.size, bool)",
             ("tests/test_adjoint_parameters.py::test_gradient_equals_central_differences",),
             "a region's parameter summed over every cell, not the region's"),
    Mutation("adjoint-body-velocity-everywhere", "fem_anim/adjoint/parameters.py",
             "        if dofs is None:\n            out[:] = values",
             "        if True:\n            out[:] = values",
             ("tests/test_adjoint_contact.py::test_body_parameters_are_the_scenes_values",),
             "a body's initial velocity parameter moves every body"),
    Mutation("adjoint-damping-alpha-not-refreshed", "fem_anim/adjoint/parameters.py",
             "        values |= {k: np.array([v]) for k, v in self.damping.items()}\n", "",
             ("tests/test_adjoint_parameters.py::test_gradient_equals_central_differences",),
             "damping.alpha/beta changed in the parameters but not in the forward's forms"),
    # -- resume: checkpoints and the trajectory a kill leaves ----------------------------------
    Mutation("checkpoint-drops-bdf2-history", "fem_anim/simulation/checkpoint.py",
             'FIELDS = ("u", "v", "a", "u_old", "v_old")', 'FIELDS = ("u", "v", "a")',
             ("tests/test_checkpoint.py::test_resume_equals_uninterrupted_for_every_integrator"
              "[bdf2]",),
             "BDF2's previous step not saved: the resumed run restarts it with implicit Euler"),
    Mutation("checkpoint-drops-kappa", "fem_anim/simulation/run_loop.py",
             "        p.ipc.restore(ck.contact)\n", "        pass\n",
             ("tests/test_checkpoint.py::test_contact_resume_inside_an_impact_is_bit_for_bit",),
             "IPC's adaptive barrier stiffness restarts from its floor 0 on resume"),
    Mutation("checkpoint-drops-contact-pattern", "fem_anim/simulation/run_loop.py",
             "        restore_pattern(sim, ck)\n", "        pass\n",
             ("tests/test_checkpoint.py::test_contact_resume_inside_an_impact_is_bit_for_bit",),
             "the Hessian's pattern grown by earlier contact pairs not restored: the direct "
             "solver rounds differently (the 4.4e-9 drift)"),
    Mutation("checkpoint-drops-pressure", "fem_anim/simulation/run_loop.py",
             "        p.fields.w.x.array[p.fields.p_dofs] = ck.pressure\n", "",
             ("tests/test_checkpoint.py::test_mixed_resume_keeps_the_pressure",),
             "the mixed formulation's Newton starts the resumed step from pressure 0"),
    Mutation("checkpoint-keys-by-position", "fem_anim/simulation/checkpoint.py",
             "    vertex = np.asarray(domain.input_index, np.int64)[nodes[:, : tdim + 1]]",
             "    x = mesh.geometry.x[:, 0]\n"
             "    step = (x.max() - x.min()) * 1e-9 if x.size else 1.0\n"
             "    vertex = np.round((x - x.min()) / step).astype(np.int64)[nodes[:, : tdim + 1]]",
             ("tests/test_checkpoint.py::test_resume_at_any_scene_extent",),
             "dofs keyed by their position quantised to 1e-9 of the extent: keys collide when a "
             "body is 1e8 m away"),
    Mutation("checkpoint-solver-is-physics", "fem_anim/simulation/checkpoint.py",
             'NOT_PHYSICS = ("solver", "output", "render")', 'NOT_PHYSICS = ("output", "render")',
             ("tests/test_checkpoint.py::test_solver_change_on_resume_is_accepted_and_said",),
             "a solver setting changed on resume refused as a change of the physics"),
    Mutation("trajectory-ignores-merged-frames", "fem_anim/output/trajectory.py",
             "                    if not self.frame_file(k).is_file() and k < merged.size \\\n",
             "                    if False and k < merged.size \\\n",
             ("tests/test_kill_resume.py::test_kill_inside_writes_then_resume[after-merge]",),
             "a kill after the frames were merged into trajectory.h5: the resume finds no frame "
             "files and refuses the run"),
    # -- mixed (u, p) with damping, obstacles and a default preset; the trade study on bodies
    Mutation("mixed-damping-of-dead-u", "fem_anim/problem/energy_terms.py",
             "            u_obj = self.fields.u if self.mixed else self.u\n",
             "            u_obj = self.u\n",
             ("tests/test_mixed_with_contact.py::test_mass_damping_decays_momentum_by_the_"
              "closed_form",),
             "the mixed dissipation taken of the collapsed u (a coefficient), not of w's u"),
    Mutation("mixed-damping-no-stiffness-part", "fem_anim/problem/energy_terms.py",
             "self.damping_beta, self.rho",
             "self.damping_beta * float(not self.mixed), self.rho",
             ("tests/test_mixed_with_contact.py::test_stiffness_damping_matches_the_"
              "displacement_formulation",),
             "beta K_0 left out of the mixed formulation's dissipation potential"),
    Mutation("mixed-obstacle-barrier-dropped", "fem_anim/problem/energy_terms.py",
             "                potential += self._of_unknown(self.contact.energy)\n",
             "                pass\n",
             ("tests/test_mixed_with_contact.py::test_incompressible_body_lands_on_a_"
              "plane",),
             "the mixed step objective without the obstacle barrier"),
    Mutation("mixed-step-bound-on-w", "fem_anim/solver/step_bounds.py",
             "        y = problem.fields.displacement_part(y)\n",
             "        pass\n",
             ("tests/test_mixed_with_contact.py::test_incompressible_body_lands_on_a_"
              "plane",),
             "the obstacle step bound reads the mixed direction (u, p) as a displacement"),
    Mutation("mixed-default-preset", "fem_anim/scene/modes.py",
             "        solver.setdefault(\"preset\", MIXED_DEFAULT_PRESET)\n",
             "        pass\n",
             ("tests/test_mixed.py::test_the_default_scene_mixed_keeps_its_damping_and_gets_a_"
              "saddle_point_preset",),
             "a mixed scene naming no preset keeps cholesky, which cannot solve it"),
    Mutation("trade-mesh-of-one-body", "fem_anim/bench/trade.py",
             "    domain = build_scene_mesh(comm, ref_scene)",
             "    from fem_anim.mesh.build import build_mesh\n"
             "    domain = build_mesh(comm, ref_scene)",
             ("tests/test_bench_trade_bodies.py::test_trade_study_runs_on_the_pile",),
             "the trade study builds the top-level [mesh], not the bodies' union"),
    Mutation("trade-p2-reference-with-contact", "fem_anim/bench/sweep.py",
             "    return \"contact\" in scene.data\n",
             "    return False\n",
             ("tests/test_bench_trade_bodies.py::test_reference_of_a_contact_scene_is_one_the_"
              "scene_allows",),
             "the reference of a contact scene asks for P2, which [contact] refuses"),
    # -- every contact scene ends (tests/test_contact_ends.py) --------------------------------
    Mutation("ccd-unbounded", "fem_anim/contact/ipc.py",
             "CCD_MAX_ITERATIONS = 10_000", "CCD_MAX_ITERATIONS = 10_000_000",
             ("tests/test_contact_ends.py::test_face_to_face_cubes_finish",),
             "tight inclusion's bisection cap back at ipctk's 1e7: one CCD call takes ~35 s"),
    Mutation("no-signal-watcher", "fem_anim/simulation/interrupt.py",
             "            self._watch()\n", "            pass\n",
             ("tests/test_contact_ends.py::test_second_signal_stops_a_run_inside_a_library_call",),
             "no watcher: a second signal inside a library call is not acted on"),
    Mutation("stiffness-bound-by-sign", "fem_anim/scene/contact_limits.py",
             "if high > MAX_BARRIER_RATIO or low < MIN_BARRIER_RATIO:", "if False:",
             ("tests/test_contact_ends.py::test_hostile_contact_settings_give_one_line_and_"
              "exit_2",),
             "contact.stiffness bounded only by its sign: 1e150 and 1e-150 accepted"),
    Mutation("handles-meet-never", "fem_anim/scene/contact_limits.py",
             "        if lo <= hi:\n            return float(lo)",
             "        if lo < hi - end:\n            return float(lo)",
             ("tests/test_contact_ends.py::test_handles_driven_into_each_other_are_refused",),
             "handles driven into each other not detected"),
    Mutation("library-error-traceback", "fem_anim/cli.py",
             "except (MemoryError, RuntimeError) as err:", "except ArithmeticError as err:",
             ("tests/test_contact_ends.py::test_library_error_is_one_line_and_exit_2",),
             "a MemoryError or RuntimeError of ipctk/PETSc reaches the user as a traceback"),
    # -- contact at animation pace: safe integrator, kappa that stays put, recorded steps --
    Mutation("contact-default-integrator", "fem_anim/scene/contact_integrator.py",
             'CONTACT_INTEGRATOR = "implicit_euler"', 'CONTACT_INTEGRATOR = "newmark"',
             ("tests/test_contact_pace.py::test_contact_scene_defaults_to_implicit_euler_and_"
              "refuses_newmark",),
             "a contact scene defaults to newmark again"),
    Mutation("contact-newmark-allowed", "fem_anim/scene/contact_integrator.py",
             'CONTACT_INTEGRATORS = ("implicit_euler", "bdf2")',
             'CONTACT_INTEGRATORS = ("implicit_euler", "bdf2", "newmark")',
             ("tests/test_contact_pace.py::test_contact_scene_defaults_to_implicit_euler_and_"
              "refuses_newmark",),
             "newmark accepted in a contact scene"),
    Mutation("kappa-rebalanced-each-step", "fem_anim/contact/ipc.py",
             "value = self.kappa_floor if self.balanced else max(kappa, self.kappa_floor)",
             "value = kappa",
             ("tests/test_contact_pace.py::test_stats_record_the_barrier_and_kappa_stays_put_"
              "at_rest",),
             "kappa re-balanced at every step start (changes while nothing changes)"),
    Mutation("stats-min-distance-unrecorded", "fem_anim/contact/ipc.py",
             '"min_distance": float(d)', '"min_distance": self.dhat',
             ("tests/test_contact_pace.py::test_stats_record_the_barrier_and_kappa_stays_put_"
              "at_rest",),
             "stats.csv records d-hat as the smallest distance"),
    Mutation("energy-line-handles-as-percent", "fem_anim/simulation/energy_report.py",
             'if report.get("moving_pins"):', 'if False:',
             ("tests/test_contact_pace.py::test_energy_line_separates_handle_work_and_is_calm_"
              "for_dissipation",),
             "a handle-driven scene gets a drift percentage again"),
    # -- Newton that settles: IPC's step test with its force check, exact Hessian near rest --
    Mutation("step-test-without-force-check", "fem_anim/solver/stopping.py",
             "                    self.forces_balanced(fnorm, x):", "                    True:",
             ("tests/test_contact_pace.py::test_each_step_satisfies_its_equations_from_the_"
              "written_outputs",),
             "IPC's step test alone ends a step (its equations no longer hold to 1e-6)"),
    Mutation("force-check-loose", "fem_anim/solver/stopping.py",
             "FORCE_TOL = 1e-6", "FORCE_TOL = 1e-3",
             ("tests/test_contact_pace.py::test_each_step_satisfies_its_equations_from_the_"
              "written_outputs",),
             "the force check asks 1e-3 of the largest force term instead of 1e-6"),
    Mutation("barrier-hessian-always-projected", "fem_anim/solver/minimiser.py",
             "self.problem.ipc.exact_hessian(True)", "self.problem.ipc.exact_hessian(False)",
             ("tests/test_contact_pace.py::test_bodies_at_rest_take_at_most_two_newton_"
              "iterations",),
             "the barrier's Hessian stays PSD-projected near rest (linear convergence)"),
    Mutation("contact-stopping-auto-is-norm", "fem_anim/solver/stopping.py",
             'return "step" if contact and not saddle and newton else "norm"',
             'return "norm"',
             ("tests/test_contact_pace.py::test_bodies_at_rest_take_at_most_two_newton_"
              "iterations",),
             "a contact scene keeps the residual-norm test relative to r0"),

    # frames at output.fps (fem_anim/simulation/frame_clock.py, run_loop.py)
    Mutation("frame-substeps-floor", "fem_anim/simulation/frame_clock.py",
             "    substeps, count = max(1, _ceil((1.0 / fps) / dt)),",
             "    substeps, count = max(1, int((1.0 / fps) / dt)),",
             ("tests/test_frame_rate.py::test_frame_clock",),
             "frame intervals split into steps longer than time.dt"),
    Mutation("frame-count-rounded", "fem_anim/simulation/frame_clock.py",
             "max(1, _ceil(steps * dt * fps))",
             "max(1, round(steps * dt * fps))",
             ("tests/test_frame_rate.py::test_frame_clock",),
             "the run stops before steps * dt when that is not a whole frame"),
    Mutation("frame-count-no-round-off", "fem_anim/simulation/frame_clock.py",
             "    return int(nearest) if abs(x - nearest) <= ROUND_OFF * max(1.0, abs(x)) else",
             "    return int(nearest) if abs(x - nearest) <= 0.0 * max(1.0, abs(x)) else",
             ("tests/test_frame_rate.py::test_frame_clock",),
             "a frame count of 9.000000000000002 taken as 10 frames"),
    Mutation("frames-by-dt-steps", "fem_anim/simulation/run_loop.py",
             "    stepper = AdaptiveStepper(sim, clock.step, sim.scene[\"time\"])",
             "    stepper = AdaptiveStepper(sim, sim.scene[\"time\"][\"dt\"], sim.scene[\"time\"])",
             ("tests/test_frame_rate.py::test_frames_are_converged_states_at_the_frame_times",),
             "steps of dt and a short one onto each frame instead of equal steps"),
    # artists' meshes (fem_anim/mesh/surface_repair.py, mesh_file.py, build.py)
    Mutation("tetwild-orientation-kept", "fem_anim/mesh/surface_repair.py",
             "    tets[negative] = tets[negative][:, [0, 2, 1, 3]]",
             "    tets[negative] = tets[negative]",
             ("tests/test_artist_meshes.py::test_broken_surface_is_filled",),
             "fTetWild's negatively oriented tetrahedra passed on"),
    Mutation("tetwild-degenerate-passed", "fem_anim/mesh/surface_repair.py",
             "    kept = triangles[~flat & once]",
             "    kept = triangles[once]",
             ("tests/test_artist_meshes.py::test_garbage_is_one_clear_error",),
             "zero-area triangles handed to fTetWild (which crashes on them)"),
    Mutation("tetwild-in-working-directory", "fem_anim/mesh/surface_repair.py",
             "capture_output=True, text=True, env=env, cwd=folder,",
             "capture_output=True, text=True, env=env,",
             ("tests/test_artist_meshes.py::test_broken_surface_is_filled",),
             "fTetWild's file written into the user's working directory"),
    Mutation("tetwild-cache-not-read", "fem_anim/mesh/surface_repair.py",
             "        with np.load(cached) as data:",
             "        with np.load(cached.with_suffix(\".none\")) as data:",
             ("tests/test_artist_meshes.py::test_a_surface_gives_the_same_tetrahedra_again",),
             "fTetWild run again: another set of tetrahedra for the same scene"),
    Mutation("mesh-units-ignored", "fem_anim/mesh/build.py",
             "        scale = LENGTH_UNITS[cfg.get(\"units\", \"m\")] * cfg.get(\"scale\", 1.0)",
             "        scale = cfg.get(\"scale\", 1.0)",
             ("tests/test_artist_meshes.py::test_units_and_scale",),
             "mesh.units not applied to the file's coordinates"),
    Mutation("auto-fill-skips-gmsh", "fem_anim/mesh/mesh_file.py",
             "    if fill != \"tetwild\":",
             "    if fill == \"gmsh\":",
             ("tests/test_artist_meshes.py::test_fill_modes",),
             "closed clean surfaces no longer filled by gmsh under mesh.fill = auto"),
    # -- shells: membrane and hinge bending (forms/shell_*.py, problem/shell_terms.py) --
    Mutation("shell-plane-stress-lambda", "forms/shell_membrane.py",
             "    return 2 * mu * lmbda / (lmbda + 2 * mu)",
             "    return lmbda",
             ("tests/test_shell.py::"
              "test_patch_uniform_stretch_gives_the_analytic_stress_and_energy",),
             "the membrane uses the 3D Lame lambda instead of the plane-stress one"),
    Mutation("shell-rest-frame-height", "forms/shell_membrane.py",
             "    h = ufl.sqrt(ufl.dot(b, b) - b_t1**2)",
             "    h = ufl.sqrt(ufl.dot(b, b))",
             ("tests/test_shell.py::"
              "test_patch_uniform_stretch_gives_the_analytic_stress_and_energy",),
             "D_m's second row takes the whole second edge, not its part normal to the first"),
    Mutation("shell-neohookean-log-area", "forms/shell_membrane.py",
             "    lnJ = ufl.ln(ufl.det(C)) / 2",
             "    lnJ = ufl.ln(ufl.det(C))",
             ("tests/test_shell.py::test_energy_gradient_hessian_equal_the_reference",),
             "ln J taken as ln det C (J^2), not half of it"),
    Mutation("shell-hinge-orientation", "fem_anim/problem/shell_terms.py",
             "        orientation = ufl.sign(ufl.dot(N(\"+\"), N(\"-\")))",
             "        orientation = 1.0",
             ("tests/test_shell.py::test_energy_gradient_hessian_equal_the_reference",
              "tests/test_shell.py::test_cylinder_bending_energy_is_kirchhoff_love"),
             "the two triangles' normals at an edge used as the mesh orients them"),
    Mutation("shell-hinge-rest-angle", "fem_anim/problem/shell_terms.py",
             "        return shell_bending.hinge_density(theta, theta_rest,",
             "        return shell_bending.hinge_density(theta, 0.0,",
             ("tests/test_shell.py::test_energy_gradient_hessian_equal_the_reference",),
             "the bending energy measured from flat, not from the rest angles"),
    Mutation("shell-hinge-edge-weight", "forms/shell_bending.py",
             "    return 3 * k * edge_length / area_sum * (theta - theta_rest) ** 2",
             "    return 3 * k / area_sum * (theta - theta_rest) ** 2",
             ("tests/test_shell.py::test_cylinder_bending_energy_is_kirchhoff_love",),
             "the hinge weight 3 |e|^2 / (A+ + A-) loses a factor |e|"),
    Mutation("shell-hinge-factor", "forms/shell_bending.py",
             "HINGE_FACTOR = 1.0 / 6.0",
             "HINGE_FACTOR = 1.0 / 3.0",
             ("tests/test_shell.py::test_cylinder_bending_energy_is_kirchhoff_love",
              "tests/test_shell.py::test_cantilever_plate_converges_at_first_order"),
             "the hinge stiffness calibrated for an equilateral mesh, not the sheets' squares"),
    Mutation("shell-area-density", "fem_anim/problem/discretisation.py",
             'mat["density"] * shell_thickness(',
             'mat["density"] + 0 * shell_thickness(',
             ("tests/test_shell.py::test_area_density_is_density_times_thickness",),
             "a shell's mass per area taken as the volume density, not rho t"),
    Mutation("shell-hessian-pattern", "fem_anim/problem/objective.py",
             "subset=self.ipc is not None or\n",
             "subset=self.ipc is not None and\n",
             ("tests/test_shell.py::test_swinging_sheet_keeps_its_energy_with_newmark",),
             "the mass matrix added to the Jacobian by the cell pattern, hinges couple more"),
    Mutation("shell-cell-energy-ghosts", "fem_anim/problem/reported_energies.py",
             "        energy.ghostUpdate(addv=PETSc.InsertMode.ADD, "
             "mode=PETSc.ScatterMode.REVERSE)\n",
             "",
             ("tests/test_shell.py::test_two_ranks_equal_serial",),
             "the hinge energy given to ghost cells is dropped under MPI"),
    Mutation("shell-non-manifold-check", "fem_anim/mesh/shell_mesh.py",
             "    if np.any(counts > 2):",
             "    if np.any(counts > 3):",
             ("tests/test_shell.py::test_bad_shell_input_is_one_line_exit_2",),
             "an edge shared by three triangles is let through"),
    # -- shot-ready pictures: camera fit, wall culling, outward surface, scene defaults -------
    Mutation("shot-fit-width-tangent", "fem_anim/render/camera.py",
             "z + np.abs(x) / tx, z + np.abs(y) / ty)",
             "z + np.abs(x) * tx, z + np.abs(y) / ty)",
             ("tests/test_render_shots.py::test_follow_keeps_a_travelling_body_the_same_size",
              "tests/test_render_shots.py::test_camera_fills_the_picture_with_the_bodies"),
             "the camera's distance from the picture's width is wrong: bodies leave the picture"),
    Mutation("shot-wall-never-culled", "fem_anim/render/scenery.py",
             "shown.append(np.dot(camera - point, normal) * np.dot(centre - point, normal) >= 0)",
             "shown.append(True)",
             ("tests/test_render_shots.py::test_a_wall_between_camera_and_bodies_is_not_drawn",),
             "a wall between camera and bodies is drawn over them"),
    Mutation("shot-faces-inward", "fem_anim/render/outer_surface.py",
             "np.cross(b - a, c - a), x[opposite] - a) > 0",
             "np.cross(b - a, c - a), x[opposite] - a) < 0",
             ("tests/test_render_shots.py::test_outer_faces_point_outwards",),
             "boundary triangles wound inwards (lit from behind)"),
    Mutation("shot-ghost-always", "fem_anim/render/render_defaults.py",
             "            resolved[key] = held",
             "            resolved[key] = True",
             ("tests/test_render_shots.py::test_defaults_by_scene_kind",),
             "the rest-shape ghost and edges drawn for free bodies too"),
    Mutation("jit-lock-of-others-renamed", "fem_anim/compat.py",
             "if str(lock) in _OWN_JIT_LOCKS and lock.stat()", "if lock.stat()",
             ("tests/test_safety.py::"
              "test_an_interruption_between_ffcx_lock_and_compile_leaves_no_lock",),
             "an interrupted run renames the lock of another process's compile (poisons it)"),
    Mutation("jit-poisoned-module-not-repaired", "fem_anim/compat.py",
             '    if lock.with_suffix(".c.cached").exists() and not lock.exists():',
             '    if False:',
             ("tests/test_safety.py::"
              "test_a_module_ready_without_its_lock_loads_instead_of_failing",),
             "a module ready without its lock recompiles and fails on .c.cached"),
    # -- wind and drag on shells (forms/aerodynamic_drag.py) --
    Mutation("drag-density-factor", "forms/aerodynamic_drag.py",
             "    return drag_coefficient * air_density * abs(s) ** 3 / 6",
             "    return drag_coefficient * air_density * abs(s) ** 3 / 3",
             ("tests/test_wind.py::test_falling_flat_follows_the_drag_law_to_terminal_velocity",
              "tests/test_wind.py::test_newmark_reaches_the_same_terminal_velocity"),
             "the drag potential's 1/6 taken as 1/3: twice the drag C_d rho_a |s| s / 2"),
    Mutation("drag-wind-sign", "forms/aerodynamic_drag.py",
             "    s = ufl.dot(rate * (u - u_anchor) - wind, n0)",
             "    s = ufl.dot(rate * (u - u_anchor) + wind, n0)",
             ("tests/test_wind.py::test_falling_flat_follows_the_drag_law_to_terminal_velocity",),
             "the relative velocity v + w instead of v - w (the wind blows the wrong way)"),
    Mutation("drag-not-normal-projected", "forms/aerodynamic_drag.py",
             "    s = ufl.dot(rate * (u - u_anchor) - wind, n0)",
             "    s = ufl.sqrt(ufl.dot(rate * (u - u_anchor) - wind, rate * (u - u_anchor) - "
             "wind) + 1e-30)",
             ("tests/test_wind.py::test_edge_on_sheet_feels_no_drag",),
             "the drag of the whole relative speed, not of its normal part (edge-on drag)"),
    Mutation("drag-lag-rate", "forms/aerodynamic_drag.py",
             "    rate = coefficient / weight  # 1 / tau",
             "    rate = weight / coefficient  # 1 / tau",
             ("tests/test_wind.py::test_falling_flat_follows_the_drag_law_to_terminal_velocity",),
             "v_{n+1} = (u - u_d) tau instead of (u - u_d) / tau"),
    Mutation("report-wind-gain-flagged", "fem_anim/simulation/energy_report.py",
             "drift > DAMPED_THRESHOLD and not blowing", "drift > DAMPED_THRESHOLD",
             ("tests/test_wind.py::test_work_of_the_wind_is_not_flagged_as_a_gain",),
             "the wind's work on a shell reported as an energy gain of the scheme"),
    Mutation("shell-obstacle-no-offset", "fem_anim/contact/obstacles.py",
             '{"normal": n, "point": p + offset * n}', '{"normal": n, "point": p}',
             ("tests/test_shell_contact.py::test_sheet_dropped_on_the_ground_rests_at_the_offset",),
             "a shell's mid-surface, not its face, kept off the ground (no t/2)"),
    Mutation("shell-ipc-no-offset", "fem_anim/contact/ipc.py",
             "        self.offset = float(offset)\n", "        self.offset = 0.0\n",
             ("tests/test_shell_contact.py::"
              "test_folded_strip_lands_on_itself_the_thickness_apart",),
             "a shell's layers kept apart by d_hat only, not its thickness"),
    Mutation("shell-ipc-boundary-only", "fem_anim/contact/contact_surface.py",
             "    if is_shell(mesh):\n", "    if False:\n",
             ("tests/test_shell_contact.py::"
              "test_folded_strip_lands_on_itself_the_thickness_apart",),
             "a shell's contact surface taken as its boundary edges, not its triangles"),
    Mutation("crossing-adjacent-excluded-wrongly", "fem_anim/contact/intersection.py",
             "        i, j = i[~shared], j[~shared]\n", "        i, j = i[shared], j[shared]\n",
             ("tests/test_shell_contact.py::"
              "test_crossing_pairs_finds_a_sheet_through_a_solid_and_through_itself",),
             "the surface check tests only adjacent triangles"),
    Mutation("crossing-barycentric", "fem_anim/contact/intersection.py",
             "(beta + gamma <= 1 + eps)", "(beta + gamma <= 2 + eps)",
             ("tests/test_shell_contact.py::"
              "test_crossing_pairs_finds_a_sheet_through_a_solid_and_through_itself",),
             "the crossing point tested against the parallelogram, not the triangle"),
    Mutation("shell-obstacle-friction-off", "fem_anim/contact/obstacles.py",
             "                 if not friction or ob[\"friction\"] > 0]",
             "                 if not friction]",
             ("tests/test_shell_contact.py::"
              "test_sheet_sliding_on_the_ground_stops_at_coulomb_deceleration",),
             "obstacle friction dropped"),
    Mutation("crossing-sweep-short", "fem_anim/contact/intersection.py",
             'hi[rows, 0].max(), side="right"', 'hi[rows, 0].min(), side="right"',
             ("tests/test_shell_contact.py::test_crossing_pairs_sweep_equals_every_pair",),
             "the sweep stops at the chunk's first x end: pairs further along are missed"),
    Mutation("shell-rest-nearer-than-offset", "fem_anim/contact/rest_check.py",
             "if offset > 0 and np.isfinite(min_distance) and min_distance <= offset:",
             "if offset > 0 and np.isfinite(min_distance) and min_distance < 0.0:",
             ("tests/test_shell_contact.py::"
              "test_a_shell_thicker_than_its_elements_apart_is_refused",),
             "a shell whose elements are nearer than its thickness at rest is accepted"),
    Mutation("render-shell-flat", "fem_anim/render/frames.py",
             'return 3 if "shell" in scene or any("shell" in b for b in bodies) else 2',
             "return 2",
             ("tests/test_shell_contact.py::test_a_shell_run_is_drawn_in_3d",
              "tests/test_shell_solid.py::test_a_shell_body_run_is_drawn_in_3d"),
             "a shell's triangles drawn as a 2D mesh (z dropped)"),
    Mutation("shell-extent-least", "fem_anim/mesh/bodies.py",
             "extent = float(spans.max() if shell else spans.min())",
             "extent = float(spans.min())",
             ("tests/test_demos.py::test_demo_runs[drape.py]",),
             "contact.dhat compared with a flat sheet's zero thickness (every sheet refused)"),
    Mutation("run-dim-from-cells", "fem_anim/runs.py",
             'return int(scene["mesh"]["dim"])', "return self.cells.shape[1] - 1",
             ("tests/test_shell_contact.py::"
              "test_sheet_dropped_on_the_ground_rests_at_the_offset",),
             "a shell run's points read back as 2D"),
    Mutation("p2-surface-wrong-split", "fem_anim/contact/p2_surface.py",
             "((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))",
             "((a, ab, bc), (ab, b, bc), (ca, bc, c), (ab, bc, ca))",
             ("tests/test_p2_mixed_contact.py::"
              "test_p2_surface_splits_each_facet_on_its_midpoint_dofs",),
             "a P2 facet's first sub-triangle takes the wrong midpoint dof"),
    Mutation("ipc-mixed-rows-unmapped", "fem_anim/contact/ipc.py",
             "rows = np.asarray(u_dofs)[rows.ravel()].astype(np.int64)",
             "rows = rows.ravel().astype(np.int64)",
             ("tests/test_p2_mixed_contact.py::"
              "test_barrier_taylor_on_p2_and_mixed_unknowns[mixed-0.5]",),
             "the barrier's gradient of a mixed unknown goes to V's dof numbers, not w's"),
    Mutation("ipc-mixed-hessian-on-v-rows", "fem_anim/contact/ipc.py",
             "return rows.reshape(-1, g), (np.asarray(nodes, np.int64) * bs + rows % bs)",
             "return rows.reshape(-1, g), (np.arange(n_owned)[:, None] * g + np.arange(g) "
             "+ start * g)",
             ("tests/test_p2_mixed_contact.py::"
              "test_barrier_taylor_on_p2_and_mixed_unknowns[mixed-0.5]",),
             "the barrier's Hessian of a mixed unknown goes to V's global rows, not w's"),
    Mutation("intersection-p2-corners-only", "fem_anim/contact/intersection.py",
             "    if cells.shape[1] == 4:\n        return unique[counts == 1]",
             "    if True:\n        return unique[counts == 1]",
             ("tests/test_p2_mixed_contact.py::"
              "test_p2_surface_splits_each_facet_on_its_midpoint_dofs",),
             "the independent check sees a P2 body's facets unsplit (its corners only)"),
    Mutation("mixed-contact-start-as-u", "fem_anim/simulation/newton_start.py",
             "p.load_guess(guess, p.x_work, apply_bcs=False)",
             "p.u.x.array[:] = guess\n        u.copy(p.x_work)",
             ("tests/test_p2_mixed_contact.py::"
              "test_incompressible_body_dropped_on_another",),
             "the collision-free start of a mixed step is copied as a displacement into w"),
    Mutation("preview-one-step-on-contact", "fem_anim/scene/modes.py",
             'if mode == "preview" and _has_contact(raw):',
             "if False:",
             ("tests/test_preview_contact.py::"
              "test_preview_on_the_pile_does_not_fail_or_gain_energy",),
             "the preview's one Newton step per step on a contact scene (the pile fails at "
             "step 1)"),
    Mutation("p2-surface-2d-unsplit", "fem_anim/contact/p2_surface.py",
             "np.stack([m, corners[:, 1]], 1)], 1)",
             "np.stack([corners[:, 0], corners[:, 1]], 1)], 1)",
             ("tests/test_p2_mixed_contact.py::"
              "test_p2_surface_in_2d_splits_each_edge_at_its_midpoint_dof",),
             "a 2D P2 boundary edge's second segment skips its midpoint dof"),
    Mutation("mixed-contact-backtracking", "fem_anim/scene/modes.py",
             "        _fill_petsc(solver, MIXED_CONTACT_PETSC)",
             "        pass",
             ("tests/test_p2_mixed_contact.py::"
              "test_incompressible_drop_impact_steps_are_not_retried",),
             "a mixed scene with contact keeps backtracking on ||r||^2, which fails at the "
             "impact"),
    Mutation("baseline-friction-unweighted", "fem_anim/bench/ipc_baseline.py",
             "gb = gb + self.h2 * self.friction.gradient(",
             "gb = gb + self.friction.gradient(",
             ("tests/test_contact_set.py::test_baseline_gradient_and_hessian",),
             "the baseline's friction gradient misses the h^2 its objective carries"),
    Mutation("contact-set-com-compared-with-itself", "fem_anim/bench/contact_set.py",
             "diff = np.max(np.abs(com_fa - com_bl), axis=1)",
             "diff = np.max(np.abs(com_fa - com_fa), axis=1)",
             ("tests/test_contact_set.py::test_reduced_set_numbers_recompute",),
             "the physics check compares fem_anim's centre-of-mass heights with themselves"),
    Mutation("contact-set-ipc-share-of-accepted", "fem_anim/bench/contact_set.py",
             '"ipc_share": sum(float(r["ipc_s"]) for r in rows) / wall,',
             '"ipc_share": sum(float(r["ipc_s"]) for r in rows) / own,',
             ("tests/test_contact_set.py::test_reduced_set_numbers_recompute",),
             "the IPC share is taken of the accepted substeps' time, not the wall time"),
    Mutation("quadrature-data-on-every-cell", "fem_anim/problem/energy_terms.py",
             "return None if reads.all() else np.flatnonzero(",
             "return None if True else np.flatnonzero(",
             ("tests/test_regions.py::"
              "test_corotated_data_is_computed_only_where_corotated_cells_read_it",),
             "corotated's SVD evaluated on every cell of a multi-material mesh again (slow)"),
    Mutation("quadrature-data-on-wrong-cells", "fem_anim/problem/energy_terms.py",
             "np.flatnonzero(reads[cells.cell_model])",
             "np.flatnonzero(~reads[cells.cell_model])",
             ("tests/test_regions.py::"
              "test_two_region_assembly_matches_reference[3-groups-and-box-three-models]",),
             "corotated's stretch trace computed on the other materials' cells instead"),
    Mutation("min-distance-squared", "fem_anim/contact/ipc.py",
             "d = np.sqrt(self._min_distance(x))  # ipctk's is d^2\n        return {",
             "d = (self._min_distance(x))\n        return {",
             ("tests/test_newton_pace.py::"
              "test_min_distance_is_the_smallest_pair_distance_in_metres",),
             "stats.csv's min_distance is ipctk's squared distance (m^2 shown as m)"),
    Mutation("contact-start-without-predictor", "fem_anim/simulation/newton_start.py",
             "    p.u.x.array[:] = u_pred", "    p.u.x.array[:] = u_last",
             ("tests/test_newton_pace.py::"
              "test_landing_stack_keeps_newton_iterations_low_with_the_predictor_start",),
             "a contact step starts Newton at x_n, not the previous velocity's predictor"),
    Mutation("exact-barrier-hessian-only-at-test-size", "fem_anim/solver/minimiser.py",
             "EXACT_NEAR = 100.0", "EXACT_NEAR = 1.0",
             ("tests/test_newton_pace.py::"
              "test_landing_stack_keeps_newton_iterations_low_with_the_predictor_start",),
             "the barrier's exact Hessian only once a step meets the test (3 iterations at rest)"),
    Mutation("dof-gather-edge-order", "fem_anim/output/dof_gather.py",
             "edges = np.unique(every[~vertex_rows], axis=0)",
             "edges = np.unique(every[~vertex_rows], axis=0)[::-1]",
             ("tests/test_trajectory_fields.py::"
              "test_p2_step_residual_recomputed_from_the_written_fields",),
             "a P2 field's edge rows written in another order than their nodes"),
    Mutation("frame-velocity-is-displacement", "fem_anim/simulation/loop.py",
             '"velocity": lambda: state.v,', '"velocity": lambda: state.u,',
             ("tests/test_trajectory_fields.py::"
              "test_p2_step_residual_recomputed_from_the_written_fields",),
             "the trajectory's velocity field holds the displacement"),
    Mutation("frame-pressure-unscaled", "fem_anim/simulation/loop.py",
             '"pressure": lambda: float(p.mu.value) * p.p.x.array}',
             '"pressure": lambda: p.p.x.array}',
             ("tests/test_trajectory_fields.py::"
              "test_mixed_pressure_written_satisfies_the_step_equations",),
             "the mixed run's pressure written as p / mu, not in Pa"),
    Mutation("resume-drops-merged-fields", "fem_anim/output/trajectory.py",
             "for name in self.nodes\n                                           if",
             "for name in ()\n                                           if",
             ("tests/test_trajectory_fields.py::"
              "test_frames_merged_before_a_kill_keep_their_fields",),
             "a resume after the merge loses the kept frames' dof fields"),
    Mutation("p2-export-vertices-only", "fem_anim/export/run_reader.py",
             "if nodes is not None and np.all(nodes[:, 0] == nodes[:, 1]):",
             "if nodes is not None:",
             ("tests/test_export_p2.py::"
              "test_p2_export_is_the_quadratic_field_on_the_refined_surface",),
             "a P2 run exported through its vertex values only (flat triangles)"),
    Mutation("p2-refine-midpoints-swapped", "fem_anim/export/boundary.py",
             "ab, bc, ca = row(a, b), row(b, c), row(c, a)",
             "ab, bc, ca = row(b, c), row(a, b), row(c, a)",
             ("tests/test_export_p2.py::"
              "test_p2_export_is_the_quadratic_field_on_the_refined_surface",),
             "the refined triangles take the wrong edge's midside dof"),
    Mutation("handle-work-unweighted", "fem_anim/simulation/handle_work.py",
             "return p.comm.allreduce(work, op=MPI.SUM) / float(p.weight.value)",
             "return p.comm.allreduce(work, op=MPI.SUM)",
             ("tests/test_energy_balance.py::"
              "test_handle_work_recomputed_from_the_written_fields",),
             "the handles' work is grad g . du, not divided by the weight w"),
    Mutation("handle-work-no-inertia", "fem_anim/simulation/handle_work.py",
             "    if p.constant_terms is not None:\n", "    if False:\n",
             ("tests/test_energy_balance.py::"
              "test_handle_work_recomputed_from_the_written_fields",),
             "the pin's force leaves out the inertia M a"),
    Mutation("handle-gain-unflagged", "fem_anim/simulation/energy_report.py",
             "gained = dissipated < -DAMPED_THRESHOLD * moved", "gained = False",
             ("tests/test_energy_balance.py::test_a_gain_beyond_the_handles_work_is_flagged",),
             "a stored energy rising beyond the handles' work passes unflagged"),
    Mutation("contact-rest-alarm", "fem_anim/simulation/energy_report.py",
             "came_to_rest = _contact(scene) and at_rest", "came_to_rest = False",
             ("tests/test_energy_balance.py::"
              "test_a_body_at_rest_on_the_ground_says_nothing_alarming",),
             "a body settled on the ground is told its step damped the motion away"),
    Mutation("dof-gather-accepts-p3", "fem_anim/output/dof_gather.py",
             "    if np.any(best > 1e-3 * second):", "    if False:",
             ("tests/test_trajectory_fields.py::test_dof_rows_hold_the_field_at_their_nodes",),
             "a P3 field's dofs (at thirds of edges) named as if at vertices and midpoints"),
    Mutation("halo-pairs-counted-twice", "fem_anim/contact/distribution.py",
             "    if halo.part.comm.size == 1:\n        return collisions",
             "    if True:\n        return collisions",
             ("tests/test_contact_distribution.py::test_distributed_contact_equals_serial",),
             "every rank evaluates every pair of its local mesh, so pairs within two ranks' "
             "halos count twice under MPI"),
    Mutation("adjoint-exact-hessian-far-out", "fem_anim/adjoint/differentiate.py",
             "    minimiser.exact_near_start = 1.0\n", "",
             ("tests/test_adjoint_contact.py::"
              "test_contact_gradient_equals_central_differences[ipc-bdf2]",),
             "the adjoint's forward takes the exact barrier Hessian 100x out and stalls"),
    Mutation("shell-rest-squared-distance", "fem_anim/contact/ipc.py",
             "                             np.sqrt(self._min_distance(x)),  # ipctk's is d^2",
             "                             self._min_distance(x),",
             ("tests/test_shell_contact.py::"
              "test_two_layers_farther_apart_than_the_thickness_are_accepted",),
             "the shell rest check compares ipctk's squared distance with the thickness"),
    Mutation("install-signal-not-deferred", "fem_anim/output/products.py",
             "        signal.signal(sig, lambda signum, frame: arrived.append(signum))\n",
             "        pass\n",
             ("tests/test_command_safety.py::test_a_signal_during_the_install_comes_after_it",),
             "a signal taken by another thread interrupts the install half way"),
    Mutation("install-signal-lost", "fem_anim/output/products.py",
             "            signal.raise_signal(arrived[0])", "            pass",
             ("tests/test_command_safety.py::test_a_signal_during_the_install_comes_after_it",),
             "a signal that came during the install is swallowed"),
    Mutation("install-signal-not-recorded", "fem_anim/output/products.py",
             "        _installed.append(Path(folder))\n", "",
             ("tests/test_command_safety.py::test_a_signal_during_the_install_comes_after_it",
              "tests/test_command_safety.py::test_a_signal_after_the_renderers_install_says_the"
              "_pictures_are_complete"),
             "the command cannot tell that its new files were installed before the signal"),
    Mutation("render-finished-then-interrupted", "fem_anim/render/process.py",
             "    if returncode == 0 or INSTALLED_THEN_STOPPED in stderr:",
             "    if INSTALLED_THEN_STOPPED in stderr:",
             ("tests/test_command_safety.py::test_a_signal_to_the_command_after_its_renderer_"
              "finished_says_so",),
             "Ctrl-C after the renderer finished says nothing was installed"),
    Mutation("render-tile-shade-one-sided", "fem_anim/render/scenery.py",
             "        normal = -normal  # the side the camera sees",
             "        pass  # the side the camera sees",
             ("tests/test_render_speed.py::test_shaded_tiles_equal_vtks_lit_tiles_3d",
              "tests/test_render_speed.py::test_plane_shade_front_and_back"),
             "a tile seen from its back shaded as if lit from behind (ambient only), not as "
             "VTK's two-sided lighting does"),
    Mutation("render-tile-shade-stale", "fem_anim/render/frames.py",
             "        self._shade_tiles()\n",
             "        self._shade_tiles() if not hasattr(self, '_shaded') else None\n"
             "        self._shaded = True\n",
             ("tests/test_render_speed.py::test_a_frame_after_others_equals_a_fresh_renderers",),
             "the tiles keep the shade of the first frame's camera when the camera turns"),
    Mutation("render-tile-unshaded", "fem_anim/render/frames.py",
             "        self._shade_tiles()\n        self.plotter.render()",
             "        self.plotter.render()",
             ("tests/test_render_speed.py::test_shaded_tiles_equal_vtks_lit_tiles_3d",
              "tests/test_render_speed.py::test_shaded_tiles_equal_vtks_lit_tiles_2d"),
             "the unlit tiles drawn in their plain colour, not the lit one"),
    Mutation("cloth-friction-mu-twice", "fem_anim/contact/ipc.py",
             '        mu = float(self.cfg["friction"])\n',
             '        mu = 2 * float(self.cfg["friction"])\n',
             ("tests/test_cloth_friction.py::"
              "test_sheet_thrown_on_a_held_sheet_stops_at_coulomb_distance",
              "tests/test_cloth_friction.py::test_free_sheets_exchange_momentum_by_friction"),
             "IPC's friction between shells applies mu twice (the deceleration is 2 mu g)"),
    Mutation("cloth-layers-refused", "fem_anim/mesh/shell_mesh.py",
             "check_one_body(points, triangles, source, several_pieces=True)",
             "check_one_body(points, triangles, source)",
             ("tests/test_cloth_friction.py::test_free_sheets_exchange_momentum_by_friction",),
             "a shell surface of two layers of cloth is refused as two bodies"),
    Mutation("cloth-cost-solve-without-factor", "fem_anim/bench/cloth_cost.py",
             '"solve_s": per_step("factor_s") + per_step("linear_solve_s")',
             '"solve_s": per_step("linear_solve_s")',
             ("tests/test_cloth_cost.py::test_cloth_cost_table_adds_up",),
             "the cloth bench's split leaves the factorisations out of the step"),
    Mutation("cloth-cost-error-against-itself", "fem_anim/bench/cloth_cost.py",
             'one["u"] - exact["u"]', 'one["u"] - one["u"]',
             ("tests/test_cloth_cost.py::test_cloth_cost_table_adds_up",),
             "the one-step run's error is measured against itself"),
    Mutation("cloth-friction-rank-dependent", "fem_anim/contact/ipc.py",
             '        mu = float(self.cfg["friction"])\n',
             '        mu = float(self.cfg["friction"]) * (1 + self.comm.rank)\n',
             ("tests/test_cloth_friction.py::test_held_slide_on_two_ranks_equals_serial",),
             "the friction pairs a rank owns feel mu times its rank plus one (2 ranks differ)"),
    Mutation("cloth-friction-epsv-without-dt", "fem_anim/contact/ipc.py",
             'float(self.cfg["epsv"]) * h)',
             'float(self.cfg["epsv"]))',
             ("tests/test_cloth_friction.py::test_sheet_on_a_held_sheet_on_a_slope[0.2]",),
             "the friction's smoothing width is eps_v (m/s) taken as a displacement, without "
             "dt: static friction creeps dt^-1 times faster"),
    Mutation("retry-wall-not-counted", "fem_anim/simulation/adaptive.py",
             "                retry_wall += time.perf_counter() - start\n", "",
             ("tests/test_adaptive.py::test_large_swing_completes_by_substepping",),
             "the discarded tries' wall time is recorded nowhere (stats, summary, stepping)"),
    Mutation("retry-wall-not-in-stepping", "fem_anim/simulation/run_loop.py",
             'row["step_wall_s"] + row.get("retry_wall_s", 0.0)', 'row["step_wall_s"] + 0.0',
             ("tests/test_adaptive.py::test_large_swing_completes_by_substepping",),
             "the retried tries' time is booked to the output phase, not stepping"),
    Mutation("inertia-lost-with-the-factor", "fem_anim/solver/hessian_choice.py",
             ('        pc.getFactorMatrix().setMumpsIcntl(13, 1)  # the inertia of the '
              'whole matrix under MPI\n'
              '        return {"mat_mumps_icntl_13": "1"}\n'
              '\n'
              '    def _negative_count(self, pc: PETSc.PC) -> int | None:\n'
              '        """The negative pivots of the factorisation of ``pc`` (set up), '
              'or None where it\n'
              "        reports no inertia: MUMPS's Cholesky INFOG(12) (under MPI only w"
              'ith ICNTL(13) = 1;\n'
              '        for an LU factorisation INFOG(12) counts off-diagonal pivots ins'
              'tead), others by\n'
              '        MatGetInertia (PETSc\'s own Cholesky; an LU factorisation has none)."""\n'
              '        factor = pc.getFactorMatrix()\n'
              '        PETSc.Sys.pushErrorHandler("ignore")\n'
              '        try:\n'
              '            if pc.getType() == "cholesky" and pc.getFactorSolverType() ='
              '= "mumps":\n'
              '                if factor.getComm().getSize() > 1 and factor.getMumpsIcn'
              'tl(13) != 1:\n'
              '                    return None\n'
              '                return int(factor.getMumpsInfog(12))\n'),
             ('        pc.getFactorMatrix().setMumpsIcntl(24, 1)  # on the first factor only\n'
              '        pc.getFactorMatrix().setMumpsIcntl(13, 1)\n'
              '        return {}\n'
              '\n'
              '    def _negative_count(self, pc: PETSc.PC) -> int | None:\n'
              '        """The negative pivots of the factorisation of ``pc`` (set up), '
              'or None where it\n'
              "        reports no inertia: MUMPS's Cholesky INFOG(12) (under MPI only w"
              'ith ICNTL(13) = 1;\n'
              '        for an LU factorisation INFOG(12) counts off-diagonal pivots ins'
              'tead), others by\n'
              '        MatGetInertia (PETSc\'s own Cholesky; an LU factorisation has none)."""\n'
              '        factor = pc.getFactorMatrix()\n'
              '        PETSc.Sys.pushErrorHandler("ignore")\n'
              '        try:\n'
              '            if pc.getType() == "cholesky" and pc.getFactorSolverType() ='
              '= "mumps":\n'
              '                if factor.getComm().getSize() > 1 and factor.getMumpsIcn'
              'tl(13) != 1:\n'
              '                    return None\n'
              '                return int(factor.getInertia()[0])  # needs ICNTL(24) = 1\n'),
             ("tests/test_newton_pace.py::"
              "test_auto_reads_the_inertia_of_every_factorisation_after_new_pairs",),
             "auto reads the inertia by MatGetInertia with ICNTL(24) set on the first MUMPS "
             "factor only: once new contact pairs make PCSetUp replace the factor it fails"),
    Mutation("inertia-icntl13-on-first-factor-only", "fem_anim/solver/minimiser.py",
             "                self.options.setdefault(name, value)\n",
             "                pass\n",
             ("tests/test_newton_pace.py::test_auto_reads_the_inertia_on_two_ranks",),
             "ICNTL(13) = 1 only on the first MUMPS factor: under MPI a factor replaced after "
             "new contact pairs counts no global inertia"),
    # -- adjoint: initial spin and displacement (tests/test_adjoint_initial.py) ---------------
    Mutation("adjoint-spin-basis-sign", "fem_anim/adjoint/parameters.py",
             '        return [("v", self._spin_field(prefix, unit, self.centre(prefix)))]',
             '        return [("v", self._spin_field(prefix, -unit, self.centre(prefix)))]',
             ("tests/test_adjoint_initial.py::"
              "test_gradient_equals_central_differences[beam-implicit_euler]",),
             "the spin's basis omega x (X - c) with the wrong sign"),
    Mutation("adjoint-spin-about-origin", "fem_anim/adjoint/parameters.py",
             "        return center_of_mass(self.problem, body)\n",
             "        return np.zeros(self.problem.d)\n",
             ("tests/test_adjoint_initial.py::"
              "test_spin_parameter_runs_the_scene_with_that_spin",),
             "a spin parameter turns the body about the origin, not its centre of mass"),
    Mutation("adjoint-centre-of-mass-fixed", "fem_anim/adjoint/parameters.py",
             '        if kind == "material" and i == 2:\n'
             '            return self._centre_bases(where)\n',
             "",
             ("tests/test_adjoint_initial.py::"
              "test_gradient_equals_central_differences[beam-bdf2]",),
             "a spinning body's centre of mass taken as independent of a region's density"),
    Mutation("adjoint-displacement-not-applied", "fem_anim/adjoint/tape.py",
             "    state = State(u=parameters.displacement_offset(p), v=v0, a=np.zeros(n))",
             "    state = State(u=np.zeros(n), v=v0, a=np.zeros(n))",
             ("tests/test_adjoint_initial.py::"
              "test_gradient_equals_central_differences[plane-implicit_euler]",),
             "the initial displacement parameter not passed to the forward run"),
    Mutation("adjoint-initial-acceleration-u0", "fem_anim/adjoint/backward.py",
             '            bar0 = {"u": bar0["u"] + u_part, "v": bar0["v"] + v_part}',
             '            bar0 = {"u": bar0["u"], "v": bar0["v"] + v_part}',
             ("tests/test_adjoint_initial.py::"
              "test_gradient_equals_central_differences[beam-newmark]",),
             "Newmark's a_0 = M^-1 (f(u_0) - C v_0) taken as independent of u_0"),
    # -- adjoint: friction coefficients (tests/test_adjoint_friction.py) -----------------------
    Mutation("adjoint-ipc-mu-sign", "fem_anim/adjoint/backward.py",
             '                grad["contact.friction"] -= self._ipc_mu_bar()',
             '                grad["contact.friction"] += self._ipc_mu_bar()',
             ("tests/test_adjoint_friction.py::"
              "test_gradient_equals_central_differences[implicit_euler-ipc]",),
             "IPC's friction coefficient's derivative with +<dR/dmu, lambda>"),
    Mutation("adjoint-ipc-mu-not-forwarded", "fem_anim/adjoint/parameters.py",
             '            self.problem.ipc.cfg["friction"] = self.friction["contact"]\n',
             "            pass\n",
             ("tests/test_adjoint_friction.py::"
              "test_friction_parameter_runs_the_scene_with_that_friction",),
             "contact.friction changed in the parameters but not in IPC's friction"),
    Mutation("adjoint-obstacle-mu-not-replaced", "fem_anim/adjoint/parameters.py",
             "                self.replacements[problem.contact.friction_coefficients[where]]"
             " = f\n",
             "",
             ("tests/test_adjoint_friction.py::"
              "test_gradient_equals_central_differences[implicit_euler-plane]",),
             "an obstacle's mu left a Constant in the adjoint's forms: its derivative is 0"),
    # -- adjoint: the gradient per cell (tests/test_adjoint_cell_gradient.py) -----------------
    Mutation("adjoint-cell-gradient-local-order", "fem_anim/adjoint/cell_gradient.py",
             "    gathered = {name: gather.gather(v) for name, v in values.items()}",
             "    gathered = dict(values)",
             ("tests/test_adjoint_cell_gradient.py::"
              "test_a_cells_value_is_the_derivative_by_that_cell_alone",),
             "the per-cell gradient written in local cell order, not the input mesh's"),
    # -- adjoint: a handle's velocity (tests/test_adjoint_handles.py) --------------------------
    Mutation("adjoint-handle-free-response-dropped", "fem_anim/adjoint/backward.py",
             '                pinned_bar = x_bar - self.vector("hlam")',
             "                pinned_bar = x_bar",
             ("tests/test_adjoint_handles.py::"
              "test_gradient_equals_central_differences[beam-implicit_euler]",),
             "a handle's pinned values taken without the free dofs' response (-H lambda)"),
    Mutation("adjoint-handle-rates-through-update", "fem_anim/adjoint/backward.py",
             "                bar = self._handle_rates_bar(bar, end.time, grad)\n",
             "                pass\n",
             ("tests/test_adjoint_handles.py::"
              "test_gradient_equals_central_differences[beam-newmark]",),
             "Newmark's handle rates treated as the integrator's update of v and a"),
    Mutation("adjoint-handle-until-ignored", "fem_anim/adjoint/parameters.py",
             "        disp[motion.dofs, i] = min(t, motion.until)",
             "        disp[motion.dofs, i] = t",
             ("tests/test_adjoint_handles.py::test_a_handle_that_stops_within_the_run",),
             "a handle's displacement taken as velocity t after it stopped"),
    Mutation("adjoint-handle-not-forwarded", "fem_anim/adjoint/parameters.py",
             "            self.problem.moving_pins[index].velocity[:] = self.handle[prefix]\n",
             "            pass\n",
             ("tests/test_adjoint_handles.py::"
              "test_handle_parameter_runs_the_scene_with_that_velocity",),
             "pin.NAME.velocity changed in the parameters but not in the handle's motion"),
    Mutation("adjoint-nodal-displacement-not-applied", "fem_anim/adjoint/parameters.py",
             '        return out if self.nodal["u"] is None else out + self.nodal["u"]',
             "        return out",
             ("tests/test_adjoint_initial.py::"
              "test_per_node_initial_state_taylor[u-0.01-beam-implicit_euler]",),
             "a per-node initial displacement not passed to the forward run"),
    # -- the adjoint's forward states: memory, revolve, disk (fem_anim/adjoint/tape.py) ----
    Mutation("adjoint-revolve-off-by-one", "fem_anim/adjoint/tape.py",
             "        for k in range(a, n):", "        for k in range(a, n - 1):",
             ("tests/test_adjoint_storage.py::test_revolve_and_disk_give_the_in_memory_gradient"
              "_bit_for_bit[implicit_euler]",),
             "a recomputed state is one step short of the one the sweep asked for"),
    Mutation("adjoint-revolve-stale-bdf2", "fem_anim/adjoint/tape.py",
             "            self._stored[n] = state\n",
             "            self._stored[n] = state if self.storage == \"memory\" else State(\n"
             "                u=state.u, v=state.v, a=state.a, time=state.time, step=state.step)\n",
             ("tests/test_adjoint_storage.py::test_revolve_and_disk_give_the_in_memory_gradient"
              "_bit_for_bit[bdf2]",),
             "a checkpoint keeps u, v, a only: BDF2 restarts from it without u_{n-1}, v_{n-1}"),
    Mutation("adjoint-disk-newmark-acceleration", "fem_anim/adjoint/tape.py",
             'a=arrays["a"],', 'a=np.zeros_like(arrays["u"]),',
             ("tests/test_adjoint_storage.py::test_revolve_and_disk_give_the_in_memory_gradient"
              "_bit_for_bit[newmark]",),
             "Newmark's acceleration is not read back from the state files"),
    Mutation("adjoint-revolve-hessian-pattern", "fem_anim/adjoint/tape.py",
             '    if "couplings" in carry:\n        fresh_hessian(sim, carry["couplings"])\n', "",
             ("tests/test_adjoint_storage.py::test_revolve_and_disk_give_the_in_memory_gradient"
              "_bit_for_bit[ipc_friction_adaptive]",),
             "a recomputed IPC step factorises the Hessian with the run's final contact pattern"),
    Mutation("adjoint-schedule-free-advance", "fem_anim/adjoint/schedule.py",
             "        total = j[None, :] + cost[s - 1][:, l - j]",
             "        total = cost[s - 1][:, l - j]",
             ("tests/test_adjoint_storage.py::test_binomial_table_equals_the_recursive_search",),
             "the schedule's table does not count the advance to a new checkpoint"),
    Mutation("adjoint-revolve-observed-dropped", "fem_anim/adjoint/tape.py",
             '        if observed and self.storage == "revolve":',
             '        if observed and self.storage == "revolve" and n not in self._stored:',
             ("tests/test_adjoint_storage.py::test_revolve_keeps_the_objective_states_only",),
             "a checkpoint the objective reads is not kept after the sweep drops it"),
    Mutation("kl-consistency-sign", "forms/shell_kirchhoff_love.py",
             "conormal(\"-\"), D, nu)) / 2\n    return -M * Theta",
             "conormal(\"-\"), D, nu)) / 2\n    return M * Theta",
             ("tests/test_shell_kl.py::test_cantilever_plate_converges_to_kirchhoff_love"
              "[right]",),
             "the interior edges' Nitsche consistency term has the wrong sign: not the plate's "
             "Euler-Lagrange equations"),
    Mutation("kl-edge-direction", "forms/shell_kirchhoff_love.py",
             "    edge = ufl.cross(N_p, conormal(\"+\"))",
             "    edge = ufl.cross(conormal(\"+\"), N_p)",
             ("tests/test_shell_kl.py::test_cantilever_plate_converges_to_kirchhoff_love"
              "[right]",),
             "the kink angle is measured about the reversed edge: Theta has the opposite sign "
             "of the slope jump, against the moments"),
    Mutation("kl-minus-side-orientation", "forms/shell_kirchhoff_love.py",
             "    B_m = sign * curvature_change(H(\"-\"), n_m)",
             "    B_m = curvature_change(H(\"-\"), n_m)",
             ("tests/test_shell_kl.py::test_energy_gradient_hessian_equal_the_reference",),
             "the '-' side's moment keeps the mesh's orientation of its triangle, not the '+' "
             "side's"),
    Mutation("kl-clamp-moment", "forms/shell_kirchhoff_love.py",
             "    M = normal_moment(curvature_change(ufl.grad(ufl.grad(u)), n), conormal",
             "    M = 0.5 * normal_moment(curvature_change(ufl.grad(ufl.grad(u)), n), conormal",
             ("tests/test_shell_kl.py::test_energy_gradient_hessian_equal_the_reference",),
             "the clamp averages its one moment with a zero one, as an interior edge would"),
    Mutation("kl-poisson-term", "forms/shell_kirchhoff_love.py",
             "    return D / 2 * ((1 - nu) * ufl.inner(B, B) + nu * ufl.tr(B) ** 2)",
             "    return D / 2 * ((1 - nu) * ufl.inner(B, B) + nu * ufl.tr(B))",
             ("tests/test_shell_kl.py::test_energy_gradient_hessian_equal_the_reference",),
             "Koiter's density without the square of the trace"),
    Mutation("kl-ffcx-tdim-counts", "fem_anim/compat.py",
             "            result = result._replace(local_derivatives=counts[:tdim])",
             "            pass",
             ("tests/test_shell_kl.py::test_surface_hessian_of_a_quadratic_field",),
             "FFCx 0.5's tables of second derivatives on a surface are left unfixed"),
    Mutation("kl-p2-quadrature", "fem_anim/problem/shell_terms.py",
             "    metadata = {\"quadrature_degree\": 0 if degree == 1 else 2}",
             "    metadata = {\"quadrature_degree\": 0 if degree == 1 else 1}",
             ("tests/test_shell_kl.py::test_energy_gradient_hessian_equal_the_reference",),
             "a P2 shell's cells and edges integrated with one point each"),
    Mutation("kl-p1-allowed", "fem_anim/scene/shell_rules.py",
             "    if element[\"degree\"] != (2 if kl else 1):",
             "    if element[\"degree\"] not in ((1, 2) if kl else (1,)):",
             ("tests/test_shell_kl.py::test_bad_kirchhoff_love_input_is_one_line_exit_2"
              "[P1]",),
             "the Kirchhoff-Love bending is accepted on P1, where grad grad u is zero"),
    Mutation("kl-rest-normal-in-cells", "fem_anim/problem/shell_terms.py",
             "            n = shell_bending.unit_normal(shell_membrane.tangent_map(u, J))\n"
             "            B = shell_kirchhoff_love",
             "            n = shell_bending.unit_normal(J)\n"
             "            B = shell_kirchhoff_love",
             ("tests/test_shell_kl.py::test_end_moment_rolls_the_strip_to_the_analytic_radius"
              "[right]",),
             "the cells' curvature projects on the rest normal: right for small rotations only"),
    Mutation("suite-selection-spawns-workers", "tests/conftest.py",
             "    if config.args_source == pytest.Config.ArgsSource.ARGS:\n        return 0\n",
             "",
             ("tests/test_suite_workers.py::test_a_selection_runs_in_this_process",),
             "a run of one file starts worker processes (each imports DOLFINx) for nothing"),
    Mutation("docs-warnings-not-errors", "tests/test_docs.py",
             '[sys.executable, "-m", "sphinx", "-W", "--keep-going",',
             '[sys.executable, "-m", "sphinx", "--keep-going",',
             ("tests/test_docs.py::test_a_broken_cross_reference_fails_the_build",),
             "the site's build passes with a broken cross-reference (warnings not errors)"),
    Mutation("contact-cost-setup-in-first-step", "fem_anim/bench/contact_cost.py",
             "split[key] = ipc.timers[key] = 0.0",
             "split[key] = 0.0",
             ("tests/test_contact_cost.py::test_printed_numbers_recompute_from_the_csvs",),
             "the contact bench counts ipctk's set-up time (before the first step) in step 1"),
    Mutation("contact-cost-baseline-from-rest", "fem_anim/bench/contact_cost.py",
             "contact_set._baseline_run(scene, sim.domain, steps, velocity)",
             "contact_set._baseline_run(scene, sim.domain, steps)",
             ("tests/test_contact_cost.py::test_baseline_follows_the_same_bodies",),
             "the baseline starts the thrown boxes at rest, not at the scene's initial velocity"),
    Mutation("contact-cost-ratio-inverted", "fem_anim/bench/contact_cost.py",
             'ratio = fa["s_per_step"] / bl["s_per_step"]',
             'ratio = bl["s_per_step"] / fa["s_per_step"]',
             ("tests/test_contact_cost.py::test_printed_numbers_recompute_from_the_csvs",),
             "the printed ratio is the baseline's s/step over fem_anim's"),
    Mutation("contact-cost-wall-without-retries", "fem_anim/bench/contact_cost.py",
             "wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)",
             'wall = comm.allreduce(time.perf_counter() - start - totals["retry_wall_s"], '
             "op=MPI.MAX)",
             ("tests/test_contact_cost.py::test_discarded_try_is_in_the_wall_time",),
             "the contact bench's step wall time leaves out fem_anim's discarded tries"),
    Mutation("contact-cost-cpu-ratio-of-wall", "fem_anim/bench/contact_cost.py",
             'cpu_ratio = fa["cpu_per_step"] / bl["cpu_per_step"]',
             'cpu_ratio = fa["s_per_step"] / bl["cpu_per_step"]',
             ("tests/test_contact_cost.py::test_printed_numbers_recompute_from_the_csvs",),
             "the CPU-time ratio divides fem_anim's wall time by the baseline's CPU time"),
    Mutation("halo-radius-unbounded", "fem_anim/contact/distribution.py",
             "self.radius = radius = float(reach(self.longest))",
             "self.radius = radius = 10 * float(reach(self.longest))",
             ("tests/test_contact_distribution.py::"
              "test_local_meshes_hold_their_share_and_a_halo",),
             "the halo reaches ten times too far: far bodies enter every rank's local mesh "
             "and each rank's detection runs over most of the surface"),
    Mutation("halo-sends-lower-ranks-facets", "fem_anim/contact/distribution.py",
             "                    mask &= top >= starts[q]",
             "                    pass",
             ("tests/test_contact_distribution.py::"
              "test_local_meshes_hold_their_share_and_a_halo",),
             "a rank receives facets whose vertices all belong to lower ranks, which serve "
             "none of its pairs"),
    Mutation("ownership-filter-unnegated", "fem_anim/contact/distribution.py",
             "at_or_above = ~ipctk.make_static_obstacle_filter(int(first))",
             "at_or_above = ipctk.make_static_obstacle_filter(int(first))",
             ("tests/test_contact_distribution.py::test_distributed_contact_equals_serial",),
             "the broad-phase filter keeps pairs below the first owned vertex instead of "
             "above it: rank 0 detects no pair, and owned pairs go missing"),
    Mutation("halo-gradient-rows-kept-local", "fem_anim/contact/distribution.py",
             "        got = self.comm.alltoall([np.ascontiguousarray(rows[s]) for s in "
             "self.slots])",
             "        got = self.comm.alltoall([np.ascontiguousarray(rows[s]) * (q == "
             "self.comm.rank) for q, s in enumerate(self.slots)])",
             ("tests/test_contact_distribution.py::test_distributed_contact_equals_serial",),
             "gradient rows of vertices owned by another rank are dropped instead of sent "
             "to their owner: a pair across two ranks pushes one side only"),
    Mutation("joint-layout-shell-over-solid", "fem_anim/mesh/joint_layout.py",
             "return self._rank_start[owner] + self._inside[owner, k] + blocks - first",
             "return self._rank_start[owner] + blocks - first",
             ("tests/test_shell_solid.py::test_joint_objective_is_the_parts_plus_the_barrier",),
             "the shell's joint blocks start at the rank's first block instead of after its "
             "solid blocks: the barrier reads and writes the solid's rows for the shell"),
    Mutation("joint-barrier-unweighted", "fem_anim/problem/joint_objective.py",
             "value += float(self.weight.value) * self.ipc.energy()",
             "value += self.ipc.energy()",
             ("tests/test_shell_solid.py::test_joint_objective_is_the_parts_plus_the_barrier",
              "tests/test_shell_solid.py::test_joint_gradient_and_hessian_pass_a_taylor_test"),
             "the joint objective adds kappa B without the weight w that its gradient and "
             "Hessian carry: the line search judges another function than Newton's"),
    Mutation("joint-hessian-half-barrier", "fem_anim/problem/joint_objective.py",
             "self.ipc.add_hessian(A, float(self.weight.value))",
             "self.ipc.add_hessian(A, 0.5 * float(self.weight.value))",
             ("tests/test_shell_solid.py::test_joint_objective_is_the_parts_plus_the_barrier",
              "tests/test_shell_solid.py::test_joint_gradient_and_hessian_pass_a_taylor_test"),
             "the joint Hessian holds half the barrier's: not the derivative of the gradient"),
    Mutation("joint-offset-dropped", "fem_anim/contact/joint_surface.py",
             "self.dhat, self.offset = float(cfg[\"dhat\"]), float(offset)",
             "self.dhat, self.offset = float(cfg[\"dhat\"]), 0.0",
             ("tests/test_shell_solid.py::test_joint_objective_is_the_parts_plus_the_barrier",
              "tests/test_shell_solid.py::test_cloth_falls_on_a_soft_cube_without_intersection"),
             "the joint barrier keeps no thickness: the cloth's mid-surface may touch the "
             "solid and layers of cloth each other"),
    Mutation("joint-barrier-spares-the-solid", "fem_anim/problem/joint_objective.py",
             "        self.ipc.add_gradient(barrier, float(self.weight.value))\n"
             "        barrier.array[self._pinned_rows] = 0.0\n        b.axpy(1.0, barrier)",
             "        self.ipc.add_gradient(barrier, float(self.weight.value))\n"
             "        barrier.array[: self.layout.offsets[1]] = 0.0\n        b.axpy(1.0, barrier)",
             ("tests/test_shell_solid.py::test_free_collision_keeps_the_total_momentum",),
             "the barrier pushes the shell but not the solid (its rows of the joint gradient "
             "dropped): no reaction, Newton's third law broken, the step does not converge"),
    Mutation("joint-offset-dropped-drape", "fem_anim/contact/joint_surface.py",
             "self.dhat, self.offset = float(cfg[\"dhat\"]), float(offset)",
             "self.dhat, self.offset = float(cfg[\"dhat\"]), 0.0",
             ("tests/test_shell_solid.py::test_cloth_falls_on_a_soft_cube_without_intersection",),
             "the joint barrier keeps no thickness: the stepped cloth comes nearer the cube "
             "than t"),
    Mutation("joint-scene-shell-offset-dropped", "fem_anim/scene/joint_rules.py",
             "mesh[\"origin\"] = [float(a + b) for a, b in zip(origin, body[\"offset\"])]",
             "mesh[\"origin\"] = origin",
             ("tests/test_shell_solid.py::"
              "test_scene_file_with_a_shell_body_runs_intersection_free",),
             "a shell body's offset is not applied to its sheet: the cloth is built inside "
             "the cube"),
    Mutation("joint-barrier-moves-pins", "fem_anim/problem/joint_objective.py",
             "        barrier.array[self._pinned_rows] = 0.0\n        b.axpy(1.0, barrier)",
             "        b.axpy(1.0, barrier)",
             ("tests/test_shell_solid.py::"
              "test_pinned_vertices_in_contact_stay_on_their_targets",),
             "the barrier's gradient is added to the pinned rows, whose residual is x - u_bc: "
             "a pinned vertex in contact is pushed off its target"),
    Mutation("joint-parts-staged-with-another-weight", "fem_anim/problem/joint_objective.py",
             "            part.stage(u0, y, weight, t, h, d)",
             "            part.stage(u0, y, weight * (1.0 + 1e-3), t, h, d)",
             ("tests/test_shell_solid.py::"
              "test_bodies_apart_step_as_their_own_runs[implicit_euler]",),
             "the parts' step objectives get another weight w than the scheme's: the joint "
             "step is not the bodies' implicit step even where they do not touch"),
    Mutation("joint-baij-preallocated-per-scalar-row", "fem_anim/problem/joint_objective.py",
             "pairs = np.unique(np.stack([np.concatenate(rows) // b, np.concatenate(cols) // b]),",
             "pairs = np.unique(np.stack([np.concatenate(rows), np.concatenate(cols)]),",
             ("tests/test_shell_solid.py::test_block_storage_solves_the_joint_step",),
             "the block matrix is preallocated with scalar rows' counts: PETSc refuses it"),
    Mutation("joint-api-run-not-dispatched", "fem_anim/runs.py",
             "    if shell_body(scene.data) is not None:  # a shell beside solids",
             "    if False:  # a shell beside solids",
             ("tests/test_shell_solid.py::test_python_api_runs_a_shell_body_scene",),
             "fem_anim.run hands a scene with a shell body to the one-mesh Simulation"),
    Mutation("joint-offset-dropped-fold", "fem_anim/contact/joint_surface.py",
             "self.dhat, self.offset = float(cfg[\"dhat\"]), float(offset)",
             "self.dhat, self.offset = float(cfg[\"dhat\"]), 0.0",
             ("tests/test_shell_solid.py::test_cloth_lands_on_itself_beside_a_solid",),
             "the joint barrier keeps no thickness: two layers of the cloth lying on each "
             "other come nearer than t"),
    Mutation("shell-export-one-sided", "fem_anim/export/usd_stage.py",
             "            mesh.CreateDoubleSidedAttr(True)",
             "            pass",
             ("tests/test_export_shell.py::test_shell_usd_is_the_trajectory_at_every_frame",),
             "a cloth exported without doubleSided: renderers that cull back faces lose half "
             "of it"),
    Mutation("shell-export-energy-unit", "fem_anim/export/run_reader.py",
             'return "J/m^2" if body in self.shells else "J/m^3"',
             'return "J/m^3"',
             ("tests/test_export_shell.py::test_shell_usd_is_the_trajectory_at_every_frame",),
             "a shell's energy density (per area) labelled J/m^3"),
    Mutation("joint-export-sorted-winding", "fem_anim/export/run_reader.py",
             "    out[on_solid] = faces[match]\n",
             "    out[on_solid] = triangles[on_solid]\n",
             ("tests/test_export_shell.py::test_joint_run_exports_the_solid_and_the_cloth",),
             "a joint run's solid exported with the seen surface's sorted (unwound) triangles"),
    Mutation("joint-export-body-order", "fem_anim/export/run_reader.py",
             "body[on_solid] = np.asarray(solid_numbers)[solid_body[owner[match]]]",
             "body[on_solid] = solid_body[owner[match]]",
             ("tests/test_export_shell.py::test_joint_body_numbers_follow_the_scene",),
             "a joint run's solids numbered in the solids' mesh, not in the scene's [[body]] "
             "order"),
    Mutation("shell-export-winding-reversed", "fem_anim/export/boundary.py",
             "        return cells.copy(), np.arange(cells.shape[0])",
             "        return cells[:, [0, 2, 1]], np.arange(cells.shape[0])",
             ("tests/test_export_shell.py::test_p2_shell_exports_its_quadratic_field_refined",),
             "a shell's triangles exported against its mesh's winding: normals flipped"),
    Mutation("export-traceback", "fem_anim/export/export_command.py",
             "        except (ValueError, KeyError, IndexError, TypeError) as err:",
             "        except FemAnimError as err:",
             ("tests/test_export_shell.py::test_unreadable_runs_are_one_line",),
             "a run the exporter cannot handle ends in a Python traceback"),
    # -- the independent check sees a body inside another (inside-check) -------------------
    Mutation("tunnel-solid-ccd-ignored", "fem_anim/simulation/newton_start.py",
             "alpha = p.ipc.step_bound(u_last - target)", "alpha = 1.0",
             ("tests/test_tunnelling.py::test_a_small_box_thrown_into_a_big_one_stays_outside",),
             "Newton starts at the predictor whatever the CCD says: a small box thrown fast "
             "starts, and stays, wholly inside a bigger one (no crossing to see)"),
    Mutation("tunnel-joint-ccd-ignored", "fem_anim/simulation/joint_loop.py",
             "alpha = p.ipc.step_bound(p.joint_array([s.u - y for s, y in zip(states, targets)]))",
             "alpha = 1.0",
             ("tests/test_tunnelling.py::test_a_small_cloth_thrown_into_a_cube_stays_outside",),
             "the joint step starts at the predictor whatever the CCD says: a small cloth "
             "thrown fast starts, and stays, wholly inside the cube"),
    Mutation("inside-check-solids-ignored", "fem_anim/contact/intersection.py",
             "            or len(enclosed_vertices(points + u, F, components, bodies))]",
             "            or False]",
             ("tests/test_intersection_check.py::"
              "test_a_box_inside_a_box_is_found_and_one_outside_is_not[1]",
              "tests/test_tunnelling.py::test_a_small_box_thrown_into_a_big_one_stays_outside"),
             "crossed_frames asks ipctk only: a box wholly inside another passes"),
    Mutation("inside-check-soup-ignored", "fem_anim/contact/intersection.py",
             "or len(enclosed_vertices(x, triangles, components, bodies)))",
             "or False)",
             ("tests/test_intersection_check.py::"
              "test_a_sheet_inside_a_cube_is_found_and_one_resting_on_it_is_not",),
             "intersecting looks for crossings only: a sheet wholly inside a cube passes"),
    Mutation("inside-winding-threshold", "fem_anim/contact/intersection.py",
             "q = q[np.abs(winding_numbers(x, mine, x[q])) > 0.5]",
             "q = q[np.abs(winding_numbers(x, mine, x[q])) > 1.5]",
             ("tests/test_intersection_check.py::"
              "test_a_box_inside_a_box_is_found_and_one_outside_is_not[2]",),
             "no winding number passes the threshold: nothing is ever inside"),
    Mutation("inside-orientation-lost", "fem_anim/contact/intersection.py",
             "oriented[flipped] = tri[flipped][:, [0, 2, 1]]",
             "oriented[flipped] = tri[flipped]",
             ("tests/test_intersection_check.py::"
              "test_the_winding_number_is_one_inside_whatever_the_triangle_order",),
             "the sorted boundary triangles are not reoriented: the winding number is garbage"),
    Mutation("inside-on-surface-counted", "fem_anim/contact/intersection.py",
             "found.append(q[start:start + step][d > tol])",
             "found.append(q[start:start + step])",
             ("tests/test_intersection_check.py::"
              "test_a_box_inside_a_box_is_found_and_one_outside_is_not[1]",),
             "a vertex on the surface (touching) with |w| > 1/2 counts as inside"),
    Mutation("inside-bbox-prefilter-dropped", "fem_anim/contact/intersection.py",
             "q = others[np.all((x[others] >= lo) & (x[others] <= hi), axis=1)]",
             "q = others",
             ("tests/test_intersection_check.py::"
              "test_only_vertices_in_a_bodys_bounding_box_get_its_winding_number",),
             "every vertex gets every body's winding number: right answers, cost grows as "
             "vertices x triangles"),
    Mutation("inside-cavity-bodies-ignored", "fem_anim/contact/intersection.py",
             "bodies = solid_bodies(cells, F, components[1])", "bodies = None",
             ("tests/test_intersection_check.py::"
              "test_a_body_in_a_cavity_is_outside_and_one_in_the_material_is_inside",),
             "each closed piece is a body: a hollow body's cavity surface is inside its outer "
             "surface, every frame of it is reported"),
    Mutation("inside-cavity-sign-lost", "fem_anim/contact/intersection.py",
             "sign = np.where(np.arange(volume.size) == outer, 1.0, -1.0) * np.sign(volume)",
             "sign = np.sign(volume)",
             ("tests/test_intersection_check.py::"
              "test_a_body_in_a_cavity_is_outside_and_one_in_the_material_is_inside",),
             "a cavity oriented like the outer surface: w = 2 in the cavity, a body resting "
             "there is reported"),
    Mutation("roundoff-without-promise", "fem_anim/solver/stopping.py",
             "abs(g_prev - g) <= resolution(g, g_prev) and \\\n"
             "                    (self.stopping != \"step\" or self.promised_nothing("
             "resolution(g, g_prev))):",
             "abs(g_prev - g) <= resolution(g, g_prev):",
             ("tests/test_exact_barrier_switch.py::"
              "test_round_off_floor_needs_a_direction_that_promised_nothing",
              "tests/test_contact_pace.py::"
              "test_each_step_satisfies_its_equations_from_the_written_outputs[pile]"),
             "a line search cut to a step g cannot resolve counts as the round-off floor: "
             "the pile's steps end with ||r|| at 1-10 % of the largest force term"),
    Mutation("exact-never-withdrawn", "fem_anim/solver/minimiser.py",
             "if taken >= (1.0 - WHOLE_STEP_TOL) * full:",
             "if True:",
             ("tests/test_exact_barrier_switch.py::"
              "test_a_shortened_exact_direction_goes_back_to_the_projection",),
             "a direction from the barrier's exact Hessian that the line search or the CCD "
             "cut keeps the exact Hessian on: the pile's steps crawl on shortened exact "
             "directions"),
    # -- a failed line search on a direction within the step test is the floor ------------
    Mutation("roundoff-small-step-ignored", "fem_anim/solver/stopping.py",
             "    return decrement <= resolution(g, g0) or small",
             "    return decrement <= resolution(g, g0)",
             ("tests/test_tunnelling.py::test_a_small_cloth_thrown_into_a_cube_stays_outside",),
             "a light cloth at rest on a soft cube: its converged step (a Newton step of "
             "4.5e-9 m, g unresolvable) raised ConvergenceError"),
    Mutation("joint-resume-drops-kappa", "fem_anim/simulation/joint_checkpoint.py",
             "    sim.problem.ipc.restore(ck.contact)\n", "    pass\n",
             ("tests/test_joint_resume.py::test_interrupted_joint_run_resumes_bit_for_bit[2]",),
             "the joint barrier's adaptive stiffness restarts from its floor 0 on resume"),
    Mutation("joint-resume-drops-shell-v", "fem_anim/simulation/joint_checkpoint.py",
             "        arrays |= part_arrays(comm, part.V, domain, s, _prefix(k))",
             "        arrays |= part_arrays(comm, part.V, domain, s if k == 0 else State(\n"
             "            s.u, 0.0 * s.v, s.a, s.u_old, s.v_old, s.time, s.step), _prefix(k))",
             ("tests/test_joint_resume.py::test_interrupted_joint_run_resumes_bit_for_bit[2]",),
             "the shell's velocity saved as zero: the resumed cloth starts its step at rest"),
    Mutation("joint-resume-drops-pattern", "fem_anim/simulation/joint_checkpoint.py",
             "            restore_couplings(sim.minimiser.A, blocks, keys, ck.couplings)",
             "            restore_couplings(sim.minimiser.A, blocks, keys, None)",
             ("tests/test_joint_resume.py::test_interrupted_joint_run_resumes_bit_for_bit[2]",),
             "the joint Hessian's pattern grown by earlier contact pairs not restored: the "
             "direct solver rounds differently"),
    Mutation("joint-resume-frame-count-off", "fem_anim/simulation/joint_run.py",
             "            len(writers[0].times) if writers[0].rank0 else 0, rows,",
             "            len(writers[0].times) - 1 if writers[0].rank0 else 0, rows,",
             ("tests/test_joint_resume.py::test_interrupted_joint_run_resumes_bit_for_bit[2]",),
             "the checkpoint counts one trajectory frame too few: the resumed trajectories "
             "lack the frame of the interruption"),
    Mutation("joint-signal-not-checkpointed", "fem_anim/simulation/joint_run.py",
             "                if not saved:\n                    checkpoint(frame)\n",
             "                pass\n",
             ("tests/test_joint_resume.py::test_interrupted_joint_run_resumes_bit_for_bit[2]",),
             "a signal off the checkpoint beat stops the run without a checkpoint at its "
             "frame: the resume repeats frame 3 from frame 2's checkpoint"),
    # -- a compile waits for another process compiling the same module --------------------
    Mutation("jit-wait-ffcx-default", "fem_anim/compat.py",
             "    wait = max(int(timeout), JIT_WAIT_S)",
             "    wait = int(timeout)",
             ("tests/test_safety.py::"
              "test_a_compile_waits_for_another_process_compiling_the_same_module",),
             "two processes compiling one module on a cold cache: the second gave up after "
             "FFCx's 10 s (\"JIT compilation timed out\")"),
    # -- the Python API resumes a stopped run ----------------------------------------------
    Mutation("api-resume-starts-over", "fem_anim/runs.py",
             "result = sim.run(outdir, quiet=quiet, resume=resume)",
             "result = sim.run(outdir, quiet=quiet, resume=False)",
             ("tests/test_python_api.py::test_a_run_stopped_by_a_signal_resumes_from_python",),
             "fem_anim.run(..., resume=True) replaces the stopped run by a new one from t = 0"),
    Mutation("api-stop-keeps-temporary-folder", "fem_anim/runs.py",
             "            if comm.rank == 0:\n                shutil.rmtree(owned, "
             "ignore_errors=True)\n            raise\n",
             "            raise\n",
             ("tests/test_python_api.py::test_resume_needs_the_stopped_runs_directory",),
             "a temporary run stopped by a signal leaves its folder (nobody can reach it)"),
    Mutation("joint-resume-ignores-merged-frames", "fem_anim/output/trajectory.py",
             "                    if not self.frame_file(k).is_file() and k < merged.size \\\n",
             "                    if False and k < merged.size \\\n",
             ("tests/test_joint_kill_resume.py::test_kill_a_joint_run_inside_writes_then_resume"
              "[-1-after]",),
             "a joint run killed after its three trajectories were merged: the resume finds no "
             "frame files and refuses the run"),
    # -- the Hessian form assembled through a d x d block matrix -------------------------
    Mutation("blocked-assembly-off", "fem_anim/problem/matrices.py",
             "BLOCKED_ASSEMBLY = True",
             "BLOCKED_ASSEMBLY = False",
             ("tests/test_blocked_assembly.py::"
              "test_blocked_hessian_equals_the_direct_one_and_keeps_the_pattern",),
             "the Hessian form inserted entry by entry into the AIJ matrix again: 2x the "
             "assembly time on the pile"),
    Mutation("blocked-assembly-stale-block", "fem_anim/problem/matrices.py",
             "        B.zeroEntries()\n",
             "",
             ("tests/test_blocked_assembly.py::"
              "test_blocked_hessian_equals_the_direct_one_and_keeps_the_pattern",),
             "the kept block matrix not zeroed: each Hessian adds the previous ones"),
    # -- the landing's line search: halving where bt cuts to a tenth ----------------------
    Mutation("landing-halving-off", "fem_anim/solver/minimiser.py",
             "HALVE_CLIPPED = True",
             "HALVE_CLIPPED = False",
             ("tests/test_landing_line_search.py::"
              "test_the_landing_halves_instead_of_cutting_to_a_tenth",),
             "PETSc's bt alone: a landing covers a tenth of the remaining fall per Newton "
             "iteration (13 iterations for the pile's first step)"),
    Mutation("landing-halving-tenth", "fem_anim/solver/minimiser.py",
             "HALVINGS = (0.5, 0.25, 0.125)",
             "HALVINGS = (0.1,)",
             ("tests/test_landing_line_search.py::"
              "test_the_landing_halves_instead_of_cutting_to_a_tenth",),
             "the pre-backtrack tries bt's own tenth: the landing's iterations come back"),
    # -- the Hessian's pattern widened at once for new contact entries -------------------
    Mutation("grow-pattern-off", "fem_anim/problem/matrices.py",
             "GROW_AT_ONCE = True",
             "GROW_AT_ONCE = False",
             ("tests/test_hessian_pattern.py::test_contact_entries_widen_the_pattern_at_once",),
             "new contact entries added one by one: each new entry of a full row copies the "
             "whole matrix"),
    Mutation("grow-pattern-wrong-columns", "fem_anim/problem/matrices.py",
             "columns = np.insert(columns, at, (missing % n).astype(PETSc.IntType))",
             "columns = np.insert(columns, at, (missing // n).astype(PETSc.IntType))",
             ("tests/test_hessian_pattern.py::test_contact_entries_widen_the_pattern_at_once",),
             "the widened pattern holds the rows' indices as columns: the pairs' entries are "
             "still missing and reallocate at insertion"),
    Mutation("step-residuals-without-obstacle-friction", "fem_anim/bench/step_residuals.py",
             "elastic = fem_petsc.assemble_vector(p.residual_form)",
             "elastic = fem_petsc.assemble_vector(p.potential_gradient_form); "
             "elastic.scale(w); elastic.axpy(-1.0, gravity)",
             ("tests/test_contact_pace.py::test_each_step_satisfies_its_equations_from_the_"
              "written_outputs[demo_pile]",),
             "the re-derived residual takes grad E's form, which has no obstacle friction: a "
             "body sliding on the ground shows ||r|| at 0.24 of the largest force term"),
    # -- the kernels' gcc flags ------------------------------------------------------------
    Mutation("jit-second-scheduling-pass", "fem_anim/problem/form_compiler.py",
             "    return flags + [\"-fno-schedule-insns2\"] if gcc_major >= 14 else flags",
             "    return flags + [\"-fno-schedule-insns2\"] if gcc_major >= 15 else flags",
             ("tests/test_form_compiler.py::"
              "test_the_second_scheduling_pass_is_off_from_gcc_14",),
             "gcc 14's second scheduling pass left on: on Debian 13 a cold cache's compiles "
             "take many times longer (the cold CI leg)"),
]


def copy_tree(dest: Path) -> None:
    """Copy the repository's working files (tracked + untracked, not ignored) into ``dest``.

    ``fem_anim.forms`` and ``fem_anim.meshes`` live in ``forms/`` and ``meshes/`` (the
    package-dir mapping of pyproject.toml); links inside the copy make the plain
    ``PYTHONPATH`` layout find them there.
    """
    listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT,
                            check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        src = ROOT / name
        if not src.is_file():
            continue  # deleted in the working tree
        target = dest / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, target)
    (dest / "fem_anim" / "forms").symlink_to(dest / "forms")
    (dest / "fem_anim" / "meshes").symlink_to(dest / "meshes")


def environment(scratch: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(scratch) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def verify_isolation(scratch: Path) -> None:
    """Python must import fem_anim (and fem_anim.forms) from the copy, not the worktree.

    Plants a sentinel in the copy's ``fem_anim/__init__.py``: ``import fem_anim`` must then
    fail with it; without it, the modules' files must lie in the copy.
    """
    init = scratch / "fem_anim" / "__init__.py"
    text = init.read_text()
    init.write_text('raise ImportError("mutation_check sentinel")\n' + text)
    broken = subprocess.run([sys.executable, "-c", "import fem_anim"], cwd=scratch,
                            env=environment(scratch), capture_output=True, text=True)
    init.write_text(text)
    if "mutation_check sentinel" not in broken.stderr:
        raise SystemExit("mutation_check: a broken fem_anim in the scratch copy still imports; "
                         "the tests would not see the mutations")
    where = subprocess.run(
        [sys.executable, "-c",
         "import fem_anim, fem_anim.forms.obstacle_contact as c, fem_anim.solver.minimiser as s;"
         "print(fem_anim.__file__); print(c.__file__); print(s.__file__)"],
        cwd=scratch, env=environment(scratch), capture_output=True, text=True, check=True)
    for line in where.stdout.split():
        if not Path(line).resolve().is_relative_to(scratch.resolve()):
            raise SystemExit(f"mutation_check: {line} is imported from outside the scratch copy")


def run_selection(scratch: Path, tests: tuple[str, ...], timeout: float) -> tuple[int, float, str]:
    """pytest on ``tests`` in the copy: (exit code, seconds, last lines of its output)."""
    start = time.perf_counter()
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", "-n", "0",
           "-m", "not slow or slow", *tests]
    # its own process group, so that a timeout also ends the mpirun (and ranks) it started
    proc = subprocess.Popen(cmd, cwd=scratch, env=environment(scratch), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        text, _ = proc.communicate(timeout=timeout)
        code = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.communicate(timeout=30)
        except subprocess.TimeoutExpired:  # SIGKILL only after SIGTERM was ignored
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
        code, text = -1, "timeout"
    tail = " | ".join(line for line in text.strip().splitlines()[-3:])
    return code, time.perf_counter() - start, tail


def check_list(mutations: list[Mutation]) -> list[str]:
    """Problems with the list itself: a missing file, an original text not found exactly once."""
    problems = []
    for m in mutations:
        path = ROOT / m.path
        if not path.is_file():
            problems.append(f"{m.name}: no file {m.path}")
            continue
        count = path.read_text().count(m.original)
        if count != 1:
            problems.append(f"{m.name}: original text occurs {count} times in {m.path}")
        if m.original == m.replacement:
            problems.append(f"{m.name}: replacement equals the original")
    names = [m.name for m in mutations]
    problems += [f"duplicate name {n}" for n in set(names) if names.count(n) > 1]
    return problems


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", nargs="*", help="names of the mutations to run")
    parser.add_argument("--list", action="store_true", help="list the mutations and exit")
    parser.add_argument("--no-baseline", action="store_true",
                        help="skip running each selection on the unmutated copy")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per pytest run")
    args = parser.parse_args(argv)
    mutations = [m for m in MUTATIONS if not args.only or m.name in args.only]
    if args.list:
        for m in mutations:
            print(f"{m.name:28s} {m.path:32s} {' '.join(m.tests)}")
        return 0
    problems = check_list(mutations)
    if args.only and len(mutations) != len(set(args.only)):
        problems.append(f"unknown names in --only: {set(args.only) - {m.name for m in MUTATIONS}}")
    if problems:
        print("\n".join(problems), file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="fem_anim_mutation_") as tmp:
        scratch = Path(tmp) / "repo"
        copy_tree(scratch)
        verify_isolation(scratch)
        print(f"scratch copy {scratch}: imports verified", flush=True)
        baseline: dict[tuple[str, ...], int] = {}
        results = []
        for m in mutations:
            if not args.no_baseline and m.tests not in baseline:
                code, seconds, tail = run_selection(scratch, m.tests, args.timeout)
                baseline[m.tests] = code
                if code != 0:
                    print(f"BASELINE FAILS {' '.join(m.tests)} ({seconds:.0f} s): {tail}",
                          flush=True)
            path = scratch / m.path
            text = path.read_text()
            path.write_text(text.replace(m.original, m.replacement, 1))
            try:
                code, seconds, tail = run_selection(scratch, m.tests, args.timeout)
            finally:
                path.write_text(text)
            # exit code 1: tests failed; 2-5: interrupted, internal or usage error, no tests
            caught = code == 1 and baseline.get(m.tests, 0) == 0
            results.append((m, caught))
            verdict = "caught" if caught else "MISSED"
            print(f"{verdict:7s} {m.name:28s} ({seconds:5.0f} s, pytest exit {code}) {tail}",
                  flush=True)
    killed = sum(caught for _, caught in results)
    print(f"kill rate: {killed}/{len(results)}"
          + (f" ({100.0 * killed / len(results):.0f} %)" if results else ""))
    missed = [m.name for m, caught in results if not caught]
    if missed:
        print("missed: " + ", ".join(missed))
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
