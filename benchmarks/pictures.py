"""Regenerate the pictures docs/ shows from the current defaults, and the numbers in their
captions (docs/benchmarks/ is the benchmark report's, written by benchmarks/report.py).

- docs/play_ur5_tool_spring.png: the saved playback page of robots/ur5_tool_spring.toml on its
  final pose (``FILE#end``), screenshot by headless Chromium (800x600, as tests/test_play.py's);
  the caption's "N steps, M damping events" in docs/playback.md is rewritten from this solve.
- docs/bistable_pendulum_energy.png: ``pinsettle.play.plot_energy`` of the bistable pendulum.
- docs/sweep_bistable_fold.png: benchmarks/sweep_fold.py.

    python benchmarks/pictures.py
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import pinsettle
from pinsettle import play

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
PLAYBACK_PAGE = DOCS / "playback.md"
#: The caption's numbers: tests/test_docs.py checks them against a fresh solve too.
CAPTION = re.compile(r"final pose: \d+ steps, \d+ damping events")


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    sys.exit("headless Chromium not found (Debian: apt-get install chromium)")


def screenshot(url: str, path: Path) -> None:
    """Chromium's screenshot of url, 800x600; tried three times (a cold Chromium sometimes
    exits before writing)."""
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader"]
    flags += ["--enable-unsafe-swiftshader", "--hide-scrollbars", "--window-size=800,600"]
    for _ in range(3):
        path.unlink(missing_ok=True)
        command = [chromium(), *flags, "--virtual-time-budget=4000", f"--screenshot={path}", url]
        subprocess.run(command, capture_output=True, timeout=120, check=False)
        if path.exists():
            return
    sys.exit(f"Chromium wrote no screenshot of {url}")


def final_pose(name: str) -> pinsettle.Result:
    """docs/play_<name>.png, the playback page on its final pose; the solve it shows."""
    scene = pinsettle.load_scene(pinsettle.scene_path(name))
    result = pinsettle.solve(scene, **play.TRACE_SETTINGS)
    with tempfile.TemporaryDirectory() as folder:
        html = Path(folder) / f"{name}.html"
        play.play(scene, result, html=html, live=False)
        screenshot(html.as_uri() + "#end", DOCS / f"play_{name}.png")
    return result


def energy_plot(name: str) -> None:
    scene = pinsettle.load_scene(pinsettle.scene_path(name))
    result = pinsettle.solve(scene, **play.TRACE_SETTINGS)
    play.plot_energy(result, DOCS / f"{name}_energy.png", title=scene.name)


def update_caption(result: pinsettle.Result) -> None:
    """The UR5 picture's caption says the steps and damping events of the solve it shows."""
    text = PLAYBACK_PAGE.read_text()
    if not CAPTION.search(text):
        sys.exit(f"{PLAYBACK_PAGE}: no caption 'final pose: N steps, M damping events' found")
    numbers = f"final pose: {result.steps} steps, {result.peaks} damping events"
    PLAYBACK_PAGE.write_text(CAPTION.sub(numbers, text))


def main() -> None:
    ur5 = final_pose("ur5_tool_spring")
    update_caption(ur5)
    energy_plot("bistable_pendulum")
    sweep = [sys.executable, str(ROOT / "benchmarks" / "sweep_fold.py")]
    subprocess.run([*sweep, "--out", str(DOCS / "sweep_bistable_fold.png")], check=True)
    print(f"ur5_tool_spring: {ur5.status}, {ur5.steps} steps, {ur5.peaks} damping events")
    print(f"wrote {DOCS}/play_ur5_tool_spring.png, bistable_pendulum_energy.png; {PLAYBACK_PAGE}")


if __name__ == "__main__":
    main()
