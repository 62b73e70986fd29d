"""Soak test of the live view (run by hand, not in CI): the server for a long session with a browser-like
client attached, its memory and its pace measured.

    python scripts/soak.py [--minutes 60] [--speed 4] [--out soak.json]

A websocket client speaking viser's protocol stays connected and drains every frame (as a browser tab
does), flicks the ball every minute and presses Reset every ten. Printed every five minutes and at the end:
the process's resident memory (VmRSS), the ticks run against those the wall clock asked for, the runs.
"""

from __future__ import annotations

import argparse
import json
import math
import threading
import time
from pathlib import Path
from typing import Any

from viewer_client import ViewerClient

from controllers import registry
from twin.viewer import FRAME_S, Viewer, serve
from twin.viewer.security import control_uuid


def rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--speed", type=float, default=4.0)
    parser.add_argument("--port", type=int, default=8093)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    ready = threading.Event()
    holder: dict[str, Any] = {}

    def on_ready(viewer: Viewer) -> None:
        holder["viewer"] = viewer
        ready.set()

    def run() -> None:
        holder["stats"] = serve(
            registry,
            port=args.port,
            speed=args.speed,
            duration_s=args.minutes * 60,
            announce=False,
            on_ready=on_ready,
        )

    server = threading.Thread(target=run, daemon=True)
    server.start()
    if not ready.wait(60):
        raise SystemExit("soak: the viewer did not start")
    viewer: Viewer = holder["viewer"]
    client = ViewerClient(args.port)

    def click(control: str) -> None:
        uuid = control_uuid(viewer.controls[control])
        client.send({"type": "GuiUpdateMessage", "uuid": uuid, "updates": {"value": True}})

    live = viewer.live
    start = time.perf_counter()
    samples: list[dict[str, float | str | None]] = []
    last_wall_s = -math.inf  # the last sample's time
    minute = 0
    while server.is_alive():
        time.sleep(1.0)
        elapsed = time.perf_counter() - start
        if elapsed >= 60 * (minute + 1) and server.is_alive():
            minute += 1
            click("reset" if minute % 10 == 0 else "flick_right")
        if elapsed >= last_wall_s + 300 or not server.is_alive():
            last_wall_s = elapsed
            sample = {
                "wall_s": round(elapsed, 1),
                "rss_mib": round(rss_mib(), 1),
                "runs": live.runs,
                "sim_time_s": round(live.rig.time_s, 2),
                "frames_received": client.frames,
                "ball_lost": live.rig.ball_lost,
                "error": live.error,
            }
            samples.append(sample)
            print(json.dumps(sample), flush=True)
    server.join()
    client.close()
    stats = holder.get("stats", {})
    wall = stats.get("wall_s", float("nan"))
    asked = wall * args.speed / FRAME_S  # ticks the wall clock asked for at this speed
    summary = {
        "minutes": args.minutes,
        "speed": args.speed,
        "rss_start_mib": samples[0]["rss_mib"],
        "rss_end_mib": samples[-1]["rss_mib"],
        "ticks": stats.get("ticks"),
        "ticks_asked": round(asked),
        "ticks_held": round(stats.get("ticks", 0) / asked, 5) if asked else None,
        "cpu_ms_per_tick": round(1e3 * stats.get("cpu_s_per_tick", float("nan")), 3),
        "runs": live.runs,
        "failures": live.failures,
        "refused": live.refused,
        "samples": samples,
    }
    print(json.dumps(summary), flush=True)
    if args.out:
        args.out.write_text(json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
