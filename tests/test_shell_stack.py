"""Where shells are not verified (DOLFINx other than 0.5), a shell scene is one clear error."""

from __future__ import annotations

import pytest

from fem_anim import compat
from fem_anim.cli import main


@pytest.mark.skipif(compat.LEGACY, reason="shells run on DOLFINx 0.5 (tests/test_shell.py)")
def test_a_shell_scene_is_refused_in_one_line(tmp_path, capsys):
    scene = tmp_path / "sheet.toml"
    scene.write_text('[mesh]\nshape = "sheet"\nsize = [1.0, 0.2]\n[shell]\nthickness = 0.001\n')
    assert main(["run", str(scene), "-q", "-o", str(tmp_path / "out")]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and "shell bodies ([shell]) run on DOLFINx 0.5 only" in lines[0]
