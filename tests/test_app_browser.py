"""Which browser the browser tests drive (twin.app.browser.find_chromium): Debian's ``chromium`` on PATH, else
``chromium-browser``, else none."""

import os
import stat
from pathlib import Path

import pytest

from twin.app.browser import find_chromium


def _executable(path: Path) -> str:
    path.write_text("#!/bin/sh\n")
    path.chmod(path.stat().st_mode | stat.S_IXUSR)
    return str(path)


@pytest.mark.quick
def test_chromium_is_found_on_path_by_either_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    first.mkdir()
    second.mkdir()
    monkeypatch.setenv("PATH", os.pathsep.join([str(first), str(second)]))
    assert find_chromium() is None
    other = _executable(second / "chromium-browser")
    assert find_chromium() == other
    debian = _executable(second / "chromium")
    assert find_chromium() == debian  # Debian's name first
    (first / "chromium").write_text("not executable\n")
    assert find_chromium() == debian
