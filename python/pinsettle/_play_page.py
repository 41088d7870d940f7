"""The pages of a playback: the static one (meshcat's viewer inline, the scene's commands, the
animation) and the live one (fed by the server), both with the same overlay (scene, status,
simulated time and speed, event counts, a flash at each event, the legend of the forces'
marks).
"""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

_OVERLAY_CSS = """
body { margin: 0; }
#meshcat-pane { width: 100vw; height: 100vh; overflow: hidden; }
#pinsettle-overlay {
  position: fixed; left: 12px; top: 12px; padding: 8px 12px; border-radius: 6px;
  font: 13px/1.45 system-ui, sans-serif; color: #212529;
  background: rgba(255, 255, 255, 0.82); pointer-events: none;
  transition: background-color 0.15s;
}
#pinsettle-overlay.flash { background: rgba(255, 176, 0, 0.85); }
#pinsettle-overlay b { font-weight: 600; }
.pinsettle-swatch {
  display: inline-block; width: 10px; height: 10px; margin-right: 6px; border-radius: 2px;
}
"""

_OVERLAY_JS = """
(function () {
  const info = JSON.parse(document.getElementById("pinsettle-info").textContent);
  const box = document.getElementById("pinsettle-overlay");
  const title = document.createElement("div");
  const clock = document.createElement("div");
  const counter = document.createElement("div");
  title.innerHTML = "<b></b> <span></span>";
  title.firstChild.textContent = info.scene;
  title.lastChild.textContent = info.status;
  box.append(title, clock, counter);
  for (const mark of info.legend || []) {  // what each mark of the forces is
    const entry = document.createElement("div");
    const swatch = document.createElement("span");
    entry.className = "pinsettle-legend";
    swatch.className = "pinsettle-swatch";
    swatch.style.background = mark.color;
    entry.append(swatch, document.createTextNode(mark.text));
    box.append(entry);
  }
  function upto(times, t) {
    let lo = 0, hi = times.length;
    while (lo < hi) {
      const mid = (lo + hi) >> 1;
      if (times[mid] <= t) lo = mid + 1; else hi = mid;
    }
    return lo;
  }
  let shown = -1;
  function tick() {  // the viewer's time is simulated time (its clips are)
    const now = (viewer.animator && viewer.animator.time) || 0;
    const t = Math.min(now, info.duration);
    const held = now >= info.duration && info.duration > 0;
    clock.textContent = "t = " + t.toFixed(3) + " s simulated, played " +
      info.speed_label + (held ? ", final pose held" : "");
    const parts = [];
    let total = 0;
    for (const kind of ["damping", "push", "rollback", "impact"]) {
      const times = info.events[kind];
      if (!times.length && kind !== "damping") continue;
      const k = upto(times, t);
      total += k;
      parts.push(kind + " events " + k + " / " + times.length);
    }
    counter.textContent = parts.join(", ");
    if (shown >= 0 && total > shown) {
      box.classList.add("flash");
      setTimeout(() => box.classList.remove("flash"), 120);
    }
    shown = total;
    requestAnimationFrame(tick);
  }
  tick();
})();
"""

# The clips run in simulated time, so that meshcat's time slider reads simulated seconds; each
# animation loaded is played at the playback's speed (its mixer's timeScale, set before the
# first frame, shown in the Animations folder), on the saved and the live page alike.
_SPEED_JS = """
(function (speed) {
  const animator = viewer.animator;
  const load = animator.load.bind(animator);
  animator.load = function (animations, options) {
    load(animations, options);
    animator.mixer.timeScale = speed;
    for (const folder of Object.values(animator.folder.__folders)) {
      for (const control of folder.__controllers) control.updateDisplay();
    }
  };
})(%s);
"""

# page.html#end opens on the final pose, paused (for a quick look, a screenshot or a test);
# page.html#t=0.05 on the frame 0.05 s of simulated time into the settle, paused.
_END_JS = """
(function () {
  const animator = viewer.animator;
  const at = location.hash === "#end" ? animator.duration
    : location.hash.startsWith("#t=") ? parseFloat(location.hash.slice(3)) : NaN;
  if (isFinite(at)) {
    const t = Math.min(Math.max(at, 0), animator.duration);
    animator.playing = false;
    animator.seek(t);
    animator.display_progress(t);  // the time slider shows it too
  }
})();
"""

_APPLY_JS = """
function pinsettle_apply(b64) {
  const text = atob(b64);
  const bytes = new Uint8Array(text.length);
  for (let i = 0; i < text.length; i++) bytes[i] = text.charCodeAt(i);
  viewer.handle_command_bytearray(bytes);
}
"""


def _speed_js(overlay: dict[str, Any] | None) -> str:
    """The hook that plays each animation loaded at the overlay's speed (simulated seconds a
    second); none without an overlay (the clips then play in real time)."""
    if overlay is None:
        return ""
    return _SPEED_JS % json.dumps(float(overlay["speed"]))


def _script_json(value: Any) -> str:
    """JSON safe inside a <script> element."""
    return json.dumps(value).replace("<", "\\u003c").replace(">", "\\u003e")


def _html(commands: list[bytes], animation: bytes | None, overlay: dict[str, Any] | None) -> str:
    """A self-contained page: meshcat's viewer (inline), the scene's commands applied in
    order, the animation in its own <script id="pinsettle-animation">, an optional overlay."""
    import meshcat

    viewer_js = (Path(meshcat.__file__).parent / "viewer" / "dist" / "main.min.js").read_text(
        encoding="utf-8"
    )
    encoded = [base64.b64encode(c).decode("ascii") for c in commands]
    parts = [
        '<!DOCTYPE html>\n<html>\n<head>\n<meta charset="utf-8">\n',
        "<title>pinsettle playback</title>\n",
        f'<style>{_OVERLAY_CSS}</style>\n</head>\n<body>\n<div id="meshcat-pane"></div>\n',
        f"<script>{viewer_js}</script>\n",
        '<script>\nvar viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));\n',
        _speed_js(overlay),
        _APPLY_JS,
        f"{_script_json(encoded)}.forEach(pinsettle_apply);\n</script>\n",
    ]
    if animation is not None:
        b64 = base64.b64encode(animation).decode("ascii")
        parts.append(f'<script id="pinsettle-animation">pinsettle_apply("{b64}");</script>\n')
        parts.append(f"<script>{_END_JS}</script>\n")
    if overlay is not None:
        parts.append(_overlay_html(overlay))
    parts.append("</body>\n</html>\n")
    return "".join(parts)


def _overlay_html(overlay: dict[str, Any]) -> str:
    """The overlay (its box, what it shows, its script), the same on the static and the live
    page."""
    return (
        '<div id="pinsettle-overlay"></div>\n'
        f'<script type="application/json" id="pinsettle-info">{_script_json(overlay)}'
        "</script>\n"
        f"<script>{_OVERLAY_JS}</script>\n"
    )


def live_page(overlay: dict[str, Any]) -> str:
    """The live page: meshcat's viewer from the server's /static/ folder, fed by its
    websocket (as meshcat's own index.html), and the overlay of the static page."""
    return "".join(
        [
            '<!DOCTYPE html>\n<html>\n<head>\n<meta charset="utf-8">\n',
            "<title>pinsettle playback</title>\n",
            f'<style>{_OVERLAY_CSS}</style>\n</head>\n<body>\n<div id="meshcat-pane"></div>\n',
            '<script src="/static/main.min.js"></script>\n',
            '<script>\nvar viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));\n',
            _speed_js(overlay),
            "viewer.connect();\n</script>\n",
            _overlay_html(overlay),
            "</body>\n</html>\n",
        ]
    )
