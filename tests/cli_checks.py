"""What a refused command line looks like, for the CLI tests: exit 2, one line on stderr, no traceback."""

from __future__ import annotations

import pytest

from twin.app.cli import main


def refused(capsys: pytest.CaptureFixture[str], argv: list[str], *needles: str) -> str:
    """Exit 2, one line on stderr containing every needle, no traceback; returns the line."""
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], lines[0]
    return lines[0]
