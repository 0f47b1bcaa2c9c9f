"""``solver.mode`` on scenes of several ``[[body]]`` tables (:mod:`fem_anim.scene.modes`).

The contract: preview fills the solver keys a scene leaves out whatever its layout, and
keeps the exact Hessian when the bodies (or a body's regions) use more than one material
model, since ``auto`` filters one model's tangent: with bodies, the models are the
bodies' own, not the (absent) top-level ``[material]``. Several bodies switch ``[contact]``
on, where the preview fills none of its one-step keys (each step solved:
tests/test_preview_contact.py); the Hessian rule holds there too. Checked through
:func:`fem_anim.scene.load_scene`, as a scene file is read.
"""

from __future__ import annotations

import pytest

from fem_anim.scene import load_scene
from fem_anim.scene.modes import SOLVER_MODES


def body(name: str, x: float, model: str | None = None, region: str | None = None) -> str:
    material = f'model = "{model}", ' if model else ""
    text = (f'[[body]]\nname = "{name}"\noffset = [{x}, 0, 0]\n'
            f'mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], divisions = [1, 1, 1] }}\n'
            f"material = {{ {material}youngs_modulus = 1e5 }}\n")
    if region:
        text += (f'[[body.region]]\nname = "half"\nmin = [{x}, 0, 0]\n'
                 f'max = [{x + 0.05}, 0.1, 0.1]\n{region}\n')
    return text


def load(tmp_path, text: str, *overrides: str):
    path = tmp_path / "bodies.toml"
    path.write_text('name = "bodies"\n' + text)
    return load_scene(path, ['solver.mode="preview"', *overrides])["solver"]


def preview_keys(solver) -> dict:
    return {k: solver[k] for k in SOLVER_MODES["preview"] if k != "petsc"}


def test_preview_on_a_body_of_one_model_is_the_full_preview(tmp_path):
    solver = load(tmp_path, body("a", 0.0, "stvk", region="youngs_modulus = 1e6"))
    expected = {k: v for k, v in SOLVER_MODES["preview"].items() if k != "petsc"}
    assert preview_keys(solver) == expected
    assert float(solver["petsc"]["ksp_rtol"]) == SOLVER_MODES["preview"]["petsc"]["ksp_rtol"]


def test_bodies_without_a_model_count_as_one_model(tmp_path):
    solver = load(tmp_path, body("a", 0.0) + body("b", 0.5))
    assert solver["hessian"] == "auto"


@pytest.mark.parametrize("models", [("stvk", "neohookean"), (None, "stvk")])
def test_bodies_of_several_models_keep_the_exact_hessian(tmp_path, models):
    solver = load(tmp_path, body("a", 0.0, models[0]) + body("b", 0.5, models[1]))
    assert solver["hessian"] == "exact"
    assert solver["max_iterations"] is None and solver["preset"] == "cholesky"  # contact


def test_a_body_region_of_another_model_keeps_the_exact_hessian(tmp_path):
    solver = load(tmp_path, body("a", 0.0, "stvk", region='model = "neohookean"')
                  + body("b", 0.5, "stvk"))
    assert solver["hessian"] == "exact"
    same = load(tmp_path, body("a", 0.0, "stvk", region="youngs_modulus = 1e6")
                + body("b", 0.5, "stvk"))
    assert same["hessian"] == "auto"


def test_an_explicit_key_still_wins_on_bodies(tmp_path):
    solver = load(tmp_path, body("a", 0.0) + body("b", 0.5), 'solver.hessian="abs"',
                  "solver.max_iterations=4")
    assert solver["hessian"] == "abs" and solver["max_iterations"] == 4
