"""The window meshcat talks to: it records every command (for the static page) and forwards
them to a live meshcat server on 127.0.0.1, run in a child process (``_meshcat_server``).
"""

from __future__ import annotations

import atexit
import os
import selectors
import subprocess
import sys
import tempfile
import time
import webbrowser
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ._play_page import _html

if TYPE_CHECKING:  # for annotations only: pyzmq comes with meshcat, when playing
    import zmq

#: Seconds to wait for the meshcat server to start or answer.
SERVER_TIMEOUT = 20.0


class _LiveServer:
    """A meshcat server on 127.0.0.1 in a child process (pinsettle._meshcat_server); with a
    ``page`` (HTML), it serves that page at /pinsettle/, its ``web_url``."""

    def __init__(self, page: str | None = None) -> None:
        command = [sys.executable, "-m", "pinsettle._meshcat_server", "--parent", str(os.getpid())]
        page_file = None
        if page is not None:  # handed over in a file, read by the server before it answers
            with tempfile.NamedTemporaryFile(
                "w", suffix=".html", prefix="pinsettle_", delete=False, encoding="utf-8"
            ) as out:
                out.write(page)
            page_file = Path(out.name)
            command += ["--page", str(page_file)]
        try:
            self._start(command)
        finally:
            if page_file is not None:
                page_file.unlink(missing_ok=True)

    def _start(self, command: list[str]) -> None:
        env = dict(os.environ)
        here = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join([here, *filter(None, [env.get("PYTHONPATH")])])
        self.process = subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
            start_new_session=True,  # Ctrl-C in a terminal reaches us, and we close it
        )
        atexit.register(self.close)
        try:
            lines = self._read_lines(2)
        except Exception:
            self.close()
            raise
        self.zmq_url = lines[0].partition("=")[2]
        self.web_url = lines[1].partition("=")[2]

    def _read_lines(self, count: int) -> list[str]:
        assert self.process.stdout is not None
        deadline = time.monotonic() + SERVER_TIMEOUT
        buffer = b""
        with selectors.DefaultSelector() as selector:
            selector.register(self.process.stdout, selectors.EVENT_READ)
            while buffer.count(b"\n") < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise RuntimeError(
                        f"the meshcat server did not start within {SERVER_TIMEOUT:.0f} s"
                    )
                if selector.select(timeout=left):
                    chunk = os.read(self.process.stdout.fileno(), 4096)
                    if not chunk:
                        self.process.wait(timeout=5)
                        assert self.process.stderr is not None
                        errors = self.process.stderr.read().decode(errors="replace").strip()
                        last = errors.splitlines()[-1] if errors else "no message"
                        raise RuntimeError(
                            f"the meshcat server exited (status {self.process.returncode}): {last}"
                        )
                    buffer += chunk
        lines = buffer.decode().splitlines()[:count]
        if not (lines[0].startswith("zmq_url=") and lines[1].startswith("web_url=")):
            raise RuntimeError(f"unexpected output from the meshcat server: {lines!r}")
        return lines

    @property
    def running(self) -> bool:
        return self.process.poll() is None

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=5)
        for stream in (self.process.stdout, self.process.stderr):
            if stream is not None:
                stream.close()
        atexit.unregister(self.close)


class _Window:
    """What a ``meshcat.Visualizer`` sends its commands to: every command is kept in a scene
    tree, as meshcat's server keeps them, for the static HTML; with a live server, it is also
    sent there (with timeouts: nothing waits forever on a dead server)."""

    def __init__(self, server: _LiveServer | None = None) -> None:
        from meshcat.servers.tree import SceneTree

        self.tree = SceneTree()
        self.animation: bytes | None = None
        self.server = server
        self.web_url = server.web_url if server else None
        self.socket: zmq.Socket[bytes] | None = None
        if server is not None:
            import zmq

            self.socket = zmq.Context.instance().socket(zmq.REQ)
            timeout_ms = int(SERVER_TIMEOUT * 1000)
            self.socket.setsockopt(zmq.RCVTIMEO, timeout_ms)
            self.socket.setsockopt(zmq.SNDTIMEO, timeout_ms)
            self.socket.setsockopt(zmq.LINGER, 0)
            self.socket.connect(server.zmq_url)

    def send(self, command: Any) -> None:
        import umsgpack
        from meshcat.servers.tree import find_node

        data = command.lower()
        packed = umsgpack.packb(data)
        kind, path = data["type"], data["path"]
        node_path = [part for part in path.split("/") if part]
        if kind == "set_transform":
            find_node(self.tree, node_path).transform = packed
        elif kind == "set_object":
            node = find_node(self.tree, node_path)
            node.object, node.properties = packed, []
        elif kind == "set_property":
            find_node(self.tree, node_path).properties.append(packed)
        elif kind == "set_animation":
            self.animation = packed
        elif kind == "delete":
            if node_path:
                find_node(self.tree, node_path[:-1]).pop(node_path[-1], None)
            else:
                from meshcat.servers.tree import SceneTree

                self.tree = SceneTree()
        if self.socket is not None:
            import zmq

            try:
                self.socket.send_multipart([kind.encode(), path.encode(), packed])
                self.socket.recv()
            except zmq.Again:
                raise RuntimeError(
                    f"the meshcat server did not answer within {SERVER_TIMEOUT:.0f} s"
                ) from None

    def commands(self) -> list[bytes]:
        """The scene as packed commands, in the order meshcat's server replays them."""
        from meshcat.servers.tree import walk

        out: list[bytes] = []
        for node in walk(self.tree):
            if node.object is not None:
                out.append(node.object)
            out.extend(node.properties)
            if node.transform is not None:
                out.append(node.transform)
        return out

    def get_scene(self) -> str:
        """The static HTML (meshcat's viewer and the recorded commands, no overlay)."""
        return _html(self.commands(), self.animation, None)

    def open(self) -> _Window:
        if self.web_url:
            webbrowser.open(self.web_url, new=2)
        return self

    def wait(self) -> str:
        return "ok"

    def get_image(self) -> Any:
        raise NotImplementedError("pinsettle's playback window does not capture images")

    def close(self) -> None:
        if self.socket is not None:
            self.socket.close(linger=0)
            self.socket = None
        if self.server is not None:
            self.server.close()
