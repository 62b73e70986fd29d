"""Soak test of the rig over the wire in real time (run by hand, not in CI): ``ballbeam serve --mode realtime``
and ``ballbeam run --rig udp://…`` as two processes on loopback for a long session, their memory and the
tick timing measured.

    python scripts/wire_soak.py [--minutes 10] [--controller appendix-sf] [--out wire_soak.json]

Printed at the end (and written to ``--out`` when given): the client's tick timing (jitter p50/p99/max of
each sample's arrival against the period, overruns), the server's counts (late and missing commands,
watchdog trips) and its pacing, and each process's resident memory (VmRSS) at the start and the end of the
session. The machine's load shows in the figures: compare them only with figures from the same run.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from twin.outputs import check_outputs, write_atomic


def rss_mib(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None  # the process has ended
    return None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=10.0)
    ap.add_argument("--controller", default="appendix-sf")
    ap.add_argument("--x0", type=float, default=0.15)
    ap.add_argument("--theta0", type=float, default=0.1)
    ap.add_argument("--out", help="write the summary as JSON here")
    args = ap.parse_args()
    if args.out:
        paths = check_outputs([("--out", args.out, (".json",), 4096)], overwrite=False)
    cli = [sys.executable, "-m", "twin.app.cli"]
    duration = f"{60 * args.minutes:g}"
    server = subprocess.Popen(
        [*cli, "serve", "--mode", "realtime", "--x0", str(args.x0), "--theta0", str(args.theta0)]
        + ["--duration", duration, "--wait-client", "30", "--json"],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert server.stdout is not None
    url = server.stdout.readline().split()[-1]  # "serving on udp://127.0.0.1:P"
    client = subprocess.Popen(
        [*cli, "run", "--rig", url, "--controller", args.controller, "--json"],
        stdout=subprocess.PIPE,
        text=True,
    )
    rss: dict[str, list[float]] = {"server": [], "client": []}
    done = threading.Event()

    def sample_memory() -> None:
        while not done.is_set():
            for name, proc in (("server", server), ("client", client)):
                value = rss_mib(proc.pid)
                if value is not None:
                    rss[name].append(value)
            done.wait(5.0)

    sampler = threading.Thread(target=sample_memory, daemon=True)
    time.sleep(3.0)  # both imported and connected: the start's memory is the session's, not the imports'
    sampler.start()
    client_out, _ = client.communicate()
    server_out, _ = server.communicate()
    done.set()
    sampler.join()
    served: dict[str, Any] = json.loads(server_out.strip().splitlines()[-1])
    ran: dict[str, Any] = json.loads(client_out.strip().splitlines()[-1])
    summary = {
        "minutes": args.minutes,
        "controller": args.controller,
        "ticks": ran["ticks"],
        "client_timing": ran.get("realtime"),
        "server_pacing": served.get("realtime"),
        "late_commands": served["late_commands"],
        "missing_commands": served["missing_commands"],
        "watchdog_trips": served["watchdog_trips"],
        "held_true_state": served["held"],
        "held_measured": ran["held"],
        "rss_mib": {name: {"start": v[0], "end": v[-1], "max": max(v)} for name, v in rss.items() if v},
    }
    text = json.dumps(summary, indent=2)
    print(text)
    if args.out:
        write_atomic(paths["--out"], text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
