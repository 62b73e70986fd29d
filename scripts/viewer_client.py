"""A browser-like client of the live view for the scripts that measure it (soak, bench): a websocket speaking
viser's protocol from the page's own origin, which sends the camera a browser sends and drains every frame."""

from __future__ import annotations

import threading
from typing import Any

import msgspec
import viser
import websockets.sync.client
from websockets.typing import Origin

__all__ = ["CAMERA", "ViewerClient"]

CAMERA = {  # what a 1400 × 900 browser tab sends first
    "type": "ViewerCameraMessage",
    "wxyz": [1.0, 0.0, 0.0, 0.0],
    "position": [0.2, -0.72, 0.52],
    "fov": 1.0,
    "near": 0.01,
    "far": 100.0,
    "image_height": 900,
    "image_width": 1400,
    "look_at": [0.0, 0.0, 0.24],
    "up_direction": [0.0, 0.0, 1.0],
}


class ViewerClient:
    """Connected to the view on ``port``; ``frames`` counts the messages received (a thread drains them)."""

    def __init__(self, port: int) -> None:
        self.ws = websockets.sync.client.connect(
            f"ws://127.0.0.1:{port}",
            origin=Origin(f"http://127.0.0.1:{port}"),
            subprotocols=[f"viser-v{viser.__version__}"],  # type: ignore[list-item]
            max_size=None,
            compression=None,
        )
        self.frames = 0
        threading.Thread(target=self._drain, daemon=True).start()
        self.send(CAMERA)

    def _drain(self) -> None:
        try:
            for _ in self.ws:
                self.frames += 1
        except websockets.exceptions.ConnectionClosed:
            pass

    def send(self, message: dict[str, Any]) -> bool:
        """Send one message; False when the server has closed the connection."""
        try:
            self.ws.send(msgspec.msgpack.encode(message))
        except websockets.exceptions.ConnectionClosed:
            return False
        return True

    def close(self) -> None:
        self.ws.close()
