"""The gradient per cell (:mod:`fem_anim.adjoint.cell_gradient`).

On the damped beam with a tip region (BDF2):

* summed over a parameter's cells it is the parameter's gradient (E, nu, rho of the rest
  and the tip, alpha, beta), and zero off them;
* per cell it is dJ/dtheta_c: a region of one cell, with the rest's values, has the
  gradient the cell has in the per-cell gradient of the scene without it (E, nu, rho),
  read from the VTU file in input cell order;
* the VTU file of 2 ranks equals the serial one to 1e-8 (this file under ``mpirun -n 2``);
* ``fem-anim fit`` writes it (``cell_gradient.vtu``, listed in the manifest), at the best
  parameters; ``fem_anim.gradient(..., per_cell=True)`` gives DG0 Functions.
"""

from __future__ import annotations

import json
import subprocess
import sys

import meshio
import numpy as np
import pytest
from conftest import ROOT, clean_environment, mpirun_command
from test_adjoint import fem_anim_cli, fit_setup, objective, scene_dict  # noqa: F401
from test_adjoint_parameters import region_scene

import fem_anim
from fem_anim.adjoint.cell_gradient import owned_cell_values, write_cell_gradient
from fem_anim.adjoint.differentiate import AdjointModel
from fem_anim.output.rundir import read_manifest

PARAMS = ["material.youngs_modulus", "material.poisson_ratio", "material.density",
          "region.tip.material.youngs_modulus", "region.tip.material.density",
          "damping.alpha", "damping.beta"]
MATERIAL = ["material.youngs_modulus", "material.poisson_ratio", "material.density"]
#: the input cell the one-cell region holds (near the free end: a large sensitivity)
CELL = 130


def test_per_cell_sums_to_the_gradient_and_is_zero_off_the_cells():
    model = AdjointModel(fem_anim.Scene.from_dict(region_scene("bdf2")), PARAMS)
    _, grad = model.evaluate(model.parameters.values(), objective())
    cells = owned_cell_values(model)
    assert sorted(cells) == sorted(PARAMS)
    tip = model.parameters.cell_mask(1)
    tip = tip[model.parameters._cell_dofs[: tip.size]]  # per owned cell
    for i, name in enumerate(PARAMS):
        assert cells[name].sum() == pytest.approx(grad[i], rel=1e-10), name
        off = ~tip if name.startswith("region.") else \
            (tip if name.startswith("material.") else np.zeros_like(tip))
        assert np.all(cells[name][off] == 0.0), name
        assert np.any(cells[name] != 0.0), name


def one_cell_region(d: dict, domain) -> dict:
    """The scene with a region holding only input cell CELL, with the material's values."""
    centroid = domain.points[domain.cells[CELL]].mean(axis=0)
    d["region"] = [{"name": "one", "min": list(centroid - 1e-6), "max": list(centroid + 1e-6),
                    "youngs_modulus": d["material"]["youngs_modulus"]}]
    return d


def test_a_cells_value_is_the_derivative_by_that_cell_alone(tmp_path):
    whole = AdjointModel(fem_anim.Scene.from_dict(scene_dict("bdf2", damped=True)), MATERIAL)
    J, _ = whole.evaluate(whole.parameters.values(), objective())
    write_cell_gradient(tmp_path / "cells.vtu", whole)
    written = meshio.read(tmp_path / "cells.vtu")
    assert written.cells[0].data.shape[0] == whole.problem.domain.cells.shape[0]
    split_scene = one_cell_region(scene_dict("bdf2", damped=True), whole.problem.domain)
    keys = [f"region.one.{name}" for name in MATERIAL]
    split = AdjointModel(fem_anim.Scene.from_dict(split_scene), keys)
    assert np.sum(split.problem.material_map.cell_material == 1) == 1
    J_split, g_split = split.evaluate(split.parameters.values(), objective())
    assert J_split == pytest.approx(J, rel=1e-12)
    for name, g in zip(MATERIAL, g_split):
        assert written.cell_data[name][0][CELL] == pytest.approx(g, rel=1e-8), name


def test_the_python_api_gives_dg0_functions():
    scene = fem_anim.Scene.from_dict(scene_dict("bdf2", damped=True))
    J, grads, cells = fem_anim.gradient(scene, objective(),
                                        ["material.youngs_modulus", "initial.velocity"],
                                        per_cell=True)
    assert list(cells) == ["material.youngs_modulus"]
    f = cells["material.youngs_modulus"]
    owned = f.function_space.dofmap.index_map.size_local
    topology = f.function_space.mesh.topology
    assert owned == topology.index_map(topology.dim).size_local  # one value per cell
    assert f.x.array[:owned].sum() == pytest.approx(grads["material.youngs_modulus"],
                                                    rel=1e-10)


def test_fit_writes_the_gradient_per_cell(fit_setup):  # noqa: F811
    root = fit_setup
    r = fem_anim_cli(["fit", "scene.toml", "--target", "ref", "--param",
                      "material.youngs_modulus", "--max-iterations", "2", "-o", "cells",
                      "-q"], root)
    assert r.returncode == 0, r.stderr
    result = json.loads((root / "cells" / "fit.json").read_text())
    written = meshio.read(root / "cells" / "cell_gradient.vtu")
    total = written.cell_data["material.youngs_modulus"][0].sum()
    assert abs(total) == pytest.approx(result["gradient_norm"], rel=1e-10)
    assert "cell_gradient.vtu" in read_manifest(root / "cells")


def mpi_cells(path: str) -> None:
    model = AdjointModel(fem_anim.Scene.from_dict(region_scene("bdf2")), PARAMS)
    model.evaluate(model.parameters.values(), objective())
    write_cell_gradient(path, model)


@pytest.mark.mpi
def test_two_ranks_write_the_serial_file(tmp_path):
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    r = subprocess.run([*mpirun, sys.executable, __file__, str(tmp_path / "two.vtu")],
                       capture_output=True, text=True, timeout=900, env=clean_environment(),
                       cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    mpi_cells(str(tmp_path / "one.vtu"))
    one, two = meshio.read(tmp_path / "one.vtu"), meshio.read(tmp_path / "two.vtu")
    np.testing.assert_array_equal(one.cells[0].data, two.cells[0].data)
    for name in PARAMS:
        a, b = one.cell_data[name][0], two.cell_data[name][0]
        np.testing.assert_allclose(b, a, rtol=1e-8, atol=1e-8 * np.abs(a).max())


if __name__ == "__main__":
    mpi_cells(sys.argv[1])
