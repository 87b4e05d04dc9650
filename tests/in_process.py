"""`rad ARGS` run in the test's own process (a subprocess would spend seconds importing what the other
commands need), for the CLI tests of the calibration commands."""

from __future__ import annotations

import io
import sys


def rad(capsys, monkeypatch, *args, stdin=None):
    """`rad ARGS` in this process: exit code, stdout, stderr."""
    from rad_core.cli import main
    if stdin is not None:
        monkeypatch.setattr(sys, 'stdin', io.StringIO(stdin))
    code = main(list(args))
    out, err = capsys.readouterr()
    return code, out, err
