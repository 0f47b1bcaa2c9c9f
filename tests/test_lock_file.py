"""The run directory's lock file (:mod:`fem_anim.output.rundir`): what it holds.

The contract: while a run holds ``.fem_anim-lock`` the file holds exactly the holder's pid
and a newline, whatever a stale lock of an earlier (dead) run held, so a refusal names the
live holder; a second claim is refused naming that pid; a released lock is taken again.
"""

from __future__ import annotations

import os

import pytest

from fem_anim.errors import FemAnimError
from fem_anim.output.rundir import LOCK, check_not_in_use, claim


def test_a_stale_lock_of_a_longer_pid_is_replaced_by_ours(tmp_path):
    out = tmp_path / "run"
    fd = claim(out)
    os.close(fd)  # the earlier run ended: its lock is released, its pid stays in the file
    (out / LOCK).write_text("4194303999\nleftover of an earlier format\n")
    fd = claim(out)
    try:
        assert (out / LOCK).read_text() == f"{os.getpid()}\n"
    finally:
        os.close(fd)


def test_a_held_directory_is_refused_naming_the_holder(tmp_path):
    out = tmp_path / "run"
    (tmp_path / "run").mkdir()
    fd = claim(out)
    try:
        # flock locks belong to an open file description: a second claim conflicts even
        # from this process
        with pytest.raises(FemAnimError, match=rf"in use by another fem-anim run \(pid "
                                               rf"{os.getpid()}\)"):
            claim(out)
        with pytest.raises(FemAnimError, match=rf"pid {os.getpid()}\)"):
            check_not_in_use(out)
    finally:
        os.close(fd)
    check_not_in_use(out)  # released: nothing to refuse
    os.close(claim(out))
