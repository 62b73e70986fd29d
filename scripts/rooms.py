"""The modules ("rooms") a command's run visits: ``ballbeam run`` in process against ``ballbeam run --rig
udp://…`` on a served twin, from the project's own files each run calls into (a profile hook records the file
of every Python function called). The remote run should visit the in-process run's rooms of the loop plus
the remote rig's, and nothing of the simulated rig but what judging needs.

    python scripts/rooms.py [--controller appendix-sf] [--duration 2]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import subprocess
import sys
import time
from pathlib import Path
from types import FrameType
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("twin", "controllers", "calib")


def rooms(argv: list[str]) -> set[str]:
    """The project files whose functions ``ballbeam ARGV`` calls (after its imports: only the run)."""
    from twin.app.cli import main

    seen: set[str] = set()

    def hook(frame: FrameType, event: str, arg: Any) -> None:
        if event == "call":
            seen.add(frame.f_code.co_filename)

    with contextlib.redirect_stdout(io.StringIO()):
        sys.setprofile(hook)
        try:
            code = main(argv)
        finally:
            sys.setprofile(None)
    print(f"ballbeam {' '.join(argv)}: exit {code}", file=sys.stderr)  # 1: not held in the short run
    out = set()
    for name in seen:
        path = Path(name).resolve()
        if path.is_relative_to(ROOT) and path.relative_to(ROOT).parts[0] in PACKAGES:
            out.add(str(path.relative_to(ROOT)))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--controller", default="appendix-sf")
    ap.add_argument("--duration", type=float, default=2.0)
    args = ap.parse_args()
    common = ["--x0", "0.1", "--theta0", "-0.1", "--duration", str(args.duration)]
    # Warm up both paths once (first-call imports and caches are not the run's rooms).
    rooms(["run", "--controller", args.controller, *common])
    local = rooms(["run", "--controller", args.controller, *common])
    port = 18000 + int(time.time()) % 1000
    serve = [
        sys.executable,
        "-m",
        "twin.app.cli",
        "serve",
        "--port",
        str(port),
        *common,
        "--wait-client",
        "30",
    ]
    server = subprocess.Popen(serve, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
    try:
        time.sleep(1.5)
        remote = rooms(["run", "--controller", args.controller, "--rig", f"udp://127.0.0.1:{port}"])
    finally:
        server.wait(timeout=60)
    print(f"in process: {len(local)} files; --rig: {len(remote)} files; both: {len(local & remote)}")
    print("only --rig:", *sorted(remote - local), sep="\n  ")
    print("only in process:", *sorted(local - remote), sep="\n  ")


if __name__ == "__main__":
    main()
