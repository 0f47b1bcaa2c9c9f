"""The version seam holds: no DOLFINx/UFL/basix/FFCx name that differs between 0.5 and 0.9
appears outside ``fem_anim/compat.py``.

Every Python file of the package, the forms, the mesh builders, the tests and the demos is
read as code (comments and strings dropped by the tokenizer, so prose may name the old API)
and searched for the names below; each hit is reported with the compat function to use.
The second test shows that the check itself catches each name.
"""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("fem_anim", "forms", "meshes", "tests", "demos")
SEAM = ROOT / "fem_anim" / "compat.py"

#: pattern -> what to use instead
FORBIDDEN = {
    r"\.vector\b(?!\s*\()": "compat.petsc_vec(u) (0.5 u.vector, 0.9 u.x.petsc_vec)",
    r"\.petsc_vec\b(?!\s*\()": "compat.petsc_vec(u)",
    r"\bVectorFunctionSpace\b|\bFunctionSpace\s*\(|\bfunctionspace\s*\(":
        "compat.vector_space / cell_space / quadrature_space",
    r"\bufl\.(VectorElement|FiniteElement|TensorElement|MixedElement)\b|\bbasix\.ufl\b":
        "compat's space and mesh constructors (0.9: basix.ufl elements)",
    r"\bstring_to_type\b|\bmake_quadrature\b": "compat.basix_cell / compat.reference_quadrature",
    r"\bExpression\s*\(": "compat.expression and compat.evaluate (eval's arguments changed)",
    r"\bjit_params\b|\bjit_options\s*=|\bform_compiler_(params|options)\b":
        "compat.expression / compat.compile_forms_together",
    r"\bdofmap\.list\b": "compat.cell_dofs(V)",
    r"\bgeometry\.dofmap\b": "compat.geometry_dofmap(mesh)",
    r"\bBoundingBoxTree\b|\bbb_tree\b|\bcompute_collisions(_points)?\b":
        "compat.colliding_cells",
    r"\bffcx\.get_(parameters|options)\b|\bFormMetaClass\b|\bform_cpp_class\b|\bffcx_jit\b"
    r"|\boriginal_coefficient_positions?\b": "compat.compile_forms_together",
    r"\b(set_bc|apply_lifting)\s*\([^)]*\b(scale|alpha)\s*=":
        "pass x0 and the factor by position (0.5 scale=, 0.9 alpha=)",
    r"\bla\.orthonormalize\b": "problem.orthonormalize (0.9 takes dolfinx vectors only)",
    r"\bgmshio\b|\bio\.gmsh\b|\bmodel_to_mesh\b": "mesh.py's own gmsh -> arrays path",
    r"\bNonlinearProblem\b": "fem_anim's own SNES (0.10 wraps SNES in NonlinearProblem)",
    r"(?<!compat)\.create_mesh\s*\(": "compat.create_mesh",
    r"\blocate_dofs_topological\b": "compat.dofs_of_cells (0.9 needs cell-cell connectivity)",
    r"\bCONVERGED_(CG_)?(NEG_CURVE|CG_CONSTRAINED|STEP_LENGTH)\b":
        "compat.trust_region_boundary_reasons() (petsc4py 3.18 and 3.22 name them apart)",
}


def code_lines(path: Path) -> list[tuple[int, str]]:
    """(line number, code) with every comment and string literal blanked out."""
    source = path.read_text(encoding="utf-8")
    lines = source.splitlines()
    blank = [list(line) for line in lines]
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type not in (tokenize.COMMENT, tokenize.STRING) and \
                getattr(tokenize, "FSTRING_MIDDLE", None) != tok.type:
            continue
        (r0, c0), (r1, c1) = tok.start, tok.end
        for r in range(r0, r1 + 1):
            row = blank[r - 1]
            start = c0 if r == r0 else 0
            end = c1 if r == r1 else len(row)
            row[start:end] = " " * (end - start)
    return [(k + 1, "".join(row)) for k, row in enumerate(blank)]


def violations(path: Path) -> list[str]:
    found = []
    for number, line in code_lines(path):
        for pattern, instead in FORBIDDEN.items():
            if re.search(pattern, line):
                name = path.relative_to(ROOT) if path.is_relative_to(ROOT) else path
                found.append(f"{name}:{number}: {line.strip()}  -> {instead}")
    return found


def python_files() -> list[Path]:
    files = [p for folder in FOLDERS for p in sorted((ROOT / folder).rglob("*.py"))]
    return [p for p in files if p != SEAM and "__pycache__" not in p.parts]


def test_no_version_specific_name_outside_compat():
    files = python_files()
    assert len(files) > 50  # the scan really reads the tree
    found = [v for path in files for v in violations(path)]
    assert not found, "version-specific names outside fem_anim/compat.py:\n" + "\n".join(found)


@pytest.mark.parametrize("line", [
    "b = u.vector.copy()",
    "b = u.x.petsc_vec",
    "V = fem.VectorFunctionSpace(mesh, ('Lagrange', 1))",
    "V = fem.functionspace(mesh, ('DG', 0))",
    "e = ufl.VectorElement('Lagrange', cell, 1)",
    "e = basix.ufl.element('Lagrange', 'triangle', 1)",
    "c = basix.cell.string_to_type('triangle')",
    "p, w = basix.make_quadrature(cell, 2)",
    "e = fem.Expression(expr, X)",
    "e = compat.expression(expr, X, jit_params=opts)",
    "dofs = V.dofmap.list.array",
    "nodes = mesh.geometry.dofmap",
    "tree = geometry.bb_tree(mesh, 3)",
    "p = ffcx.get_parameters()",
    "fem_petsc.set_bc(b, bcs, scale=0.0)",
    "fem_petsc.apply_lifting(b, [a], bcs=[bcs], x0=[x], alpha=-1.0)",
    "la.orthonormalize(vectors)",
    "mesh, ct, ft = gmshio.model_to_mesh(model, comm, 0)",
    "m = dolfinx.mesh.create_mesh(comm, cells, x, domain)",
    "dofs = fem.locate_dofs_topological(V, 3, cells)",
])
def test_the_check_catches_each_name(tmp_path, line):
    path = tmp_path / "probe.py"
    path.write_text(f"# a probe\n{line}  # comment\n'''u.vector in a docstring'''\n")
    assert len(violations(path)) >= 1
    path.write_text(f"# {line}\n'''{line}'''\nx = 1\n")
    assert violations(path) == []
