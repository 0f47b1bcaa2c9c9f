"""The mutation check's list cannot rot: every planted bug still applies, every test exists.

``tests/tools/mutation_check.py`` (not run by CI) plants each bug of its list in a scratch copy
and runs the named tests. This fast test fails when the code changes under the list: an
original text that no longer occurs exactly once, or a selected test that no longer exists.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))
from mutation_check import MUTATIONS, ROOT, check_list  # noqa: E402


def test_every_original_text_occurs_once():
    assert check_list(MUTATIONS) == []
    assert len(MUTATIONS) >= 20


def test_every_selected_test_exists():
    for m in MUTATIONS:
        assert m.tests, m.name
        for node in m.tests:
            path, _, name = node.partition("::")
            function = re.sub(r"\[.*\]$", "", name)
            text = (ROOT / path).read_text()
            assert re.search(rf"^def {re.escape(function)}\(", text, re.M), (m.name, node)
