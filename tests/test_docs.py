"""The documentation: the Sphinx site builds without a warning, and the README is a guide.

The site is built from a copy of ``docs/`` in a temporary folder (the build writes generated
pages into its source folder), never inside the clone; every warning (a broken
cross-reference included) fails the build. The README's TOML scenes are validated like files
and run for two steps, and the README stays a short guide (at most 250 lines).
"""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_README_LINES = 250


def _sphinx_build(tmp_path: Path, docs: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
         str(docs), str(tmp_path / "html")],
        capture_output=True, text=True, cwd=tmp_path, timeout=600,
        env={**os.environ, "FEM_ANIM_ROOT": str(ROOT)})


def _copy_docs(tmp_path: Path) -> Path:
    docs = tmp_path / "docs"
    shutil.copytree(ROOT / "docs", docs, ignore=shutil.ignore_patterns(
        "_build", "api", "demos", "jupyter_execute"))
    return docs


needs_sphinx = pytest.mark.skipif(
    any(importlib.util.find_spec(m) is None for m in ("sphinx", "myst_nb", "furo", "jupytext")),
    reason="the docs extra is not installed (pip install -e '.[docs]', done by .ci/setup)")


@pytest.fixture(scope="module")
def built_docs(tmp_path_factory):
    """The site built once from a copy of ``docs/``: (build folder, its docs copy, result)."""
    tmp_path = tmp_path_factory.mktemp("site")
    docs = _copy_docs(tmp_path)
    return tmp_path, docs, _sphinx_build(tmp_path, docs)


@needs_sphinx
def test_docs_build_without_warnings(built_docs):
    tmp_path, _, result = built_docs
    assert result.returncode == 0, "sphinx-build -W failed:\n" + result.stderr[-6000:]
    assert (tmp_path / "html" / "scene_reference.html").exists()
    page = (tmp_path / "html" / "scene_reference.html").read_text()
    assert "youngs_modulus" in page and "poisson_ratio" in page


@needs_sphinx
def test_a_broken_cross_reference_fails_the_build(built_docs):
    """The built site rebuilt with one page broken (Sphinx re-reads only that page) fails."""
    tmp_path, docs, _ = built_docs
    page = docs / "contact.md"
    text = page.read_text()
    page.write_text(text + "\nSee {doc}`no_such_page` and [this](no_such_file.md).\n")
    try:
        result = _sphinx_build(tmp_path, docs)
    finally:
        page.write_text(text)
    assert result.returncode != 0
    assert "no_such_page" in result.stderr


def test_readme_is_a_short_guide():
    lines = README.read_text().splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines"


def readme_scenes() -> list[str]:
    """The README's TOML code blocks."""
    return re.findall(r"```toml\n(.*?)```", README.read_text(), re.S)


def test_readme_has_a_one_body_and_a_two_body_scene():
    scenes = readme_scenes()
    assert len(scenes) >= 2
    assert any("[[body]]" in s and "[contact]" in s for s in scenes)
    assert any("[[body]]" not in s for s in scenes)


@pytest.mark.parametrize("index", range(len(readme_scenes())))
def test_readme_scene_runs(tmp_path, index):
    scene = tmp_path / "scene.toml"
    scene.write_text(readme_scenes()[index])
    result = subprocess.run(
        [sys.executable, "-m", "fem_anim", "run", str(scene), "-o", str(tmp_path / "out"),
         "-q", "--set", "time.steps=2", "--set", "output.render=false",
         "--set", "mesh.element_size=0.1"] if "[[body]]" not in readme_scenes()[index] else
        [sys.executable, "-m", "fem_anim", "run", str(scene), "-o", str(tmp_path / "out"),
         "-q", "--set", "time.steps=2", "--set", "output.render=false"],
        capture_output=True, text=True, cwd=tmp_path, timeout=600)
    assert result.returncode == 0, result.stderr[-3000:]
    assert (tmp_path / "out" / "stats.csv").exists()
