"""Playback (pinsettle play): static HTML for every scene, the energy plot, the live server on
127.0.0.1, what the animation ends on, and screenshots of both pages in headless Chromium.

The screenshots need Chromium, and most tests the viz extra (meshcat, matplotlib): without them
these tests skip with the reason, except where PINSETTLE_REQUIRE_CHROMIUM=1 (set by .ci/run),
where their absence is a failure. The missing-extra message is tested in every case."""

from __future__ import annotations

import html as html_lib
import importlib
import json
import os
import re
import shutil
import subprocess
import sys
import urllib.request
import warnings
from pathlib import Path

import numpy as np
import pinocchio
import pinsettle
import pytest

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
SCENES = sorted(p.stem for p in ROBOTS.glob("*.toml"))

# The tests that need neither meshcat nor matplotlib: they run whatever is installed.
WITHOUT_VIZ = {
    "test_solving_never_imports_meshcat_or_matplotlib",
    "test_missing_extra_is_a_clear_message",
}


@pytest.fixture(autouse=True)
def viz_extra(request):
    """Every other test needs the viz extra: it skips without it, except where
    PINSETTLE_REQUIRE_CHROMIUM=1 (CI), where a missing or broken viz dependency fails."""
    if request.function.__name__ in WITHOUT_VIZ:
        return
    for module in ("meshcat", "matplotlib"):
        try:
            importlib.import_module(module)
        except ImportError as error:
            if os.environ.get("PINSETTLE_REQUIRE_CHROMIUM") == "1":
                pytest.fail(
                    f"the viz extra is required here (PINSETTLE_REQUIRE_CHROMIUM=1) but "
                    f"{module} does not import: {error}"
                )
            pytest.skip(f"the viz extra ({module}) is not installed: {error}")


def _play():
    return importlib.import_module("pinsettle.play")


# --- what solving leaves out -----------------------------------------------------------------


def test_solving_never_imports_meshcat_or_matplotlib():
    code = (
        "import sys, pinsettle\n"
        "scene = pinsettle.load_scene(pinsettle.scene_path('bistable_pendulum'))\n"
        "r = pinsettle.solve(scene, trace_every=1, trace_configurations=True)\n"
        "assert r.converged\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in "
        "('meshcat', 'matplotlib', 'pinsettle.play')))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_missing_extra_is_a_clear_message(tmp_path):
    # meshcat made unimportable in a child process: play says what to install, exit 2.
    code = (
        "import sys; sys.modules['meshcat'] = None\n"
        "from pinsettle.__main__ import main\n"
        f"sys.exit(main(['play', 'pendulum', '--html', r'{tmp_path / 'p.html'}', '--no-open']))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 2
    assert "meshcat" in out.stderr and "pip install 'pinsettle[viz]'" in out.stderr
    assert "Traceback" not in out.stderr
    assert not (tmp_path / "p.html").exists()


@pytest.mark.parametrize(
    "args, pattern",
    [
        (["--speed", "-1"], "--speed must be a positive number"),
        (["--speed", "fast"], "--speed must be a positive number"),
        (["--html", "/no/such/folder/x.html"], "--html /no/such/folder/x.html: no such folder"),
        (["--kt", "2"], "kt"),
    ],
)
def test_bad_play_flags(args, pattern):
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "play", "pendulum", "--no-open", *args],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2, proc.stderr
    assert pattern in proc.stderr and "Traceback" not in proc.stderr


def test_play_checks_its_arguments():
    play = _play()
    scene = pinsettle.load_scene(pinsettle.scene_path("pendulum"))
    with pytest.raises(ValueError, match="speed must be a positive finite number"):
        play.play(scene, speed=0.0, live=False)
    with pytest.raises(TypeError, match="speed must be a positive number"):
        play.play(scene, speed="x", live=False)
    untraced = pinsettle.solve(scene)
    with pytest.raises(ValueError, match="no recorded configurations"):
        play.play(scene, untraced, live=False)


# --- the static page and what its animation ends on ------------------------------------------


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """Every scene played to a static page and an energy plot, once."""
    folder = tmp_path_factory.mktemp("play")
    play = _play()
    cache = {}

    def get(name):
        if name not in cache:
            scene = pinsettle.load_scene(ROBOTS / f"{name}.toml")
            result = pinsettle.solve(scene, **play.TRACE_SETTINGS)
            html, plot = folder / f"{name}.html", folder / f"{name}_energy.png"
            viz = play.play(scene, result, html=html, plot=plot, live=False)
            cache[name] = (scene, result, viz, html, plot)
        return cache[name]

    return get


@pytest.mark.parametrize("name", SCENES)
def test_every_scene_exports_a_self_contained_page_and_a_plot(name, exported):
    scene, result, viz, html, plot = exported(name)
    text = html.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>") and "MeshCat.Viewer" in text
    # Self-contained: no script, style or mesh fetched from anywhere.
    assert "<script src" not in text and 'href="http' not in text
    assert "package://" not in text
    png = plot.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    # Time scaled: a long settle plays in a few seconds.
    assert viz.timeline.duration <= 10.0
    assert viz.timeline.sim_time == pytest.approx(result.sim_time)


@pytest.mark.parametrize("name", SCENES)
def test_the_animation_ends_on_the_final_pose(name, exported):
    scene, result, viz, html, plot = exported(name)
    # Where each visual shape is at result.q, computed here with Pinocchio.
    model, visual = viz.model, viz.visual_model
    data, gdata = model.createData(), visual.createData()
    pinocchio.forwardKinematics(model, data, result.q)
    pinocchio.updateGeometryPlacements(model, data, visual, gdata)
    clips = {str(path.lower()): clip for path, clip in viz.animation.clips.items()}
    for g, obj in enumerate(visual.geometryObjects):
        clip = clips[f"/meshcat/pinsettle/pinocchio/visuals/{obj.name}"]
        position = clip.tracks["position"]
        assert np.allclose(position.values[-1], gdata.oMg[g].translation, atol=1e-9), obj.name
        # ... at the end of the motion (the viewer keeps the last keyframe's pose).
        assert position.frames[-1] == pytest.approx(viz.timeline.end * _play().FPS)
        # The shape's linear map, rotation times mesh scale: a mirrored mesh (talos's right
        # side, scale (1, -1, 1)) is sent as a negative x scale on a rotation turned about z.
        x, y, z, w = clip.tracks["quaternion"].values[-1]
        turned = pinocchio.Quaternion(w, x, y, z).toRotationMatrix()
        scale = clip.tracks["scale"].values[-1] if "scale" in clip.tracks else [1.0, 1.0, 1.0]
        expected = gdata.oMg[g].rotation @ np.diag(obj.meshScale)
        assert np.allclose(turned @ np.diag(scale), expected, atol=1e-9), obj.name
    # Springs end between their attachment points at result.q.
    pinocchio.updateFramePlacements(model, data)
    for s, spring in enumerate(scene.springs):
        a = data.oMf[model.getFrameId(spring.a_frame)].act(np.array(spring.a_point))
        b = data.oMf[model.getFrameId(spring.b_frame)].act(np.array(spring.b_point))
        track = clips[f"/meshcat/pinsettle/springs/{s}"].tracks["scale"]
        assert track.values[-1][2] == pytest.approx(np.linalg.norm(a - b), rel=1e-9)


def test_the_energy_plot_of_a_run_without_steps_has_a_time_axis(tmp_path):
    # free_fall is refused before its first step: one sample at t = 0, no simulated time.
    # Its axis is one time step long (matplotlib warned of a singular axis before).
    play = _play()
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    result = pinsettle.solve(scene, **play.TRACE_SETTINGS)
    assert result.status == "no_equilibrium" and result.steps == 0 and result.sim_time == 0
    assert list(result.trace.time) == [0.0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning of the plot fails the test
        path = play.plot_energy(result, tmp_path / "free_fall.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    plot = importlib.import_module("pinsettle._play_plot")
    assert plot._time_range(np.asarray(result.trace.time), result) == (0.0, result.dt)
    assert result.dt > 0


def test_damping_events_are_marked(exported):
    scene, result, viz, html, plot = exported("bistable_pendulum")
    assert len(viz.timeline.events["damping"]) == result.peaks > 0
    text = html.read_text(encoding="utf-8")
    assert "damping events" in text  # the on-page counter


def _drawn_marks(viz) -> dict[str, set[int]]:
    """Every node the playback drew a shape at, but the mechanism's own shapes: its path under
    the playback's root (/meshcat/pinsettle) and its materials' colours (none for a mesh file
    drawn in its own)."""
    import umsgpack
    from meshcat.servers.tree import find_node

    mechanism = {
        viz.getViewerNodeName(obj, pinocchio.GeometryType.VISUAL)
        for obj in viz.visual_model.geometryObjects
    }
    marks: dict[str, set[int]] = {}

    def walk(node, path):
        if node.object is not None and path not in mechanism:
            materials = umsgpack.unpackb(node.object)["object"].get("materials") or []
            marks[path] = {m["color"] for m in materials if "color" in m}
        for name, child in node.items():
            walk(child, f"{path}/{name}" if path else name)

    walk(find_node(viz.window.tree, ["meshcat", "pinsettle"]), "")
    return marks


def _check_legend_covers_the_marks(viz, html_text: str) -> None:
    """Every mark drawn is named by an entry of the legend (its path matches the entry's
    ``nodes``), each entry stands for marks drawn, its swatch in the colour of one of them;
    the page carries that legend."""
    from fnmatch import fnmatch

    legend = viz._overlay()["legend"]
    marks = _drawn_marks(viz)
    for path in marks:
        entries = [e for e in legend if any(fnmatch(path, n) for n in e["nodes"])]
        assert entries, f"{viz.scene.name}: the mark {path} is in no entry of the legend {legend}"
    for entry in legend:
        covered = [p for p in marks if any(fnmatch(p, n) for n in entry["nodes"])]
        assert covered, f"{viz.scene.name}: the entry {entry['text']!r} stands for no mark drawn"
        colours = set().union(*(marks[p] for p in covered))
        assert int(entry["color"][1:], 16) in colours, (entry, colours)
    info = re.search(r'id="pinsettle-info">(.*?)</script>', html_text, re.S)
    assert info and json.loads(info.group(1))["legend"] == legend


@pytest.mark.parametrize("name", SCENES)
def test_every_mark_drawn_is_in_the_legend(name, exported):
    scene, result, viz, html, plot = exported(name)
    _check_legend_covers_the_marks(viz, html.read_text("utf-8"))


def test_the_legend_names_the_springs_and_the_flashes(exported):
    scene, result, viz, html, plot = exported("ur5_tool_spring")
    marks = _drawn_marks(viz)
    # The spring (a coil and its two ends) and the damping flash are drawn ...
    assert {"springs/0", "springs/0_a", "springs/0_b", "events/damping"} <= set(marks)
    # ... and named: the coil's stiffness, the number of damping events.
    texts = {entry["text"] for entry in viz._overlay()["legend"]}
    (spring,) = scene.springs
    assert f"coil between two dark balls: spring (k = {spring.stiffness:.3g} N/m)" in texts
    damping = f"a damping event ({result.peaks}; gone on the final pose)"
    assert any(text.endswith(damping) for text in texts), texts


def test_the_damping_flash_fades_and_is_gone_on_the_final_pose(exported):
    play = _play()
    for name in SCENES:
        scene, result, viz, html, plot = exported(name)
        timeline, clips = viz.timeline, _clips(viz)
        grid = timeline.frame_times()
        for kind in ("damping", "push", "rollback"):
            clip = clips.get(f"/meshcat/pinsettle/events/{kind}")
            times = timeline.events[kind]
            # Where it would show: FLASH_SECONDS from each event, before the final pose.
            since = grid[:, None] - times[None, :]
            showing = np.any((since >= 0) & (since < play.FLASH_SECONDS), axis=1)
            showing &= grid < timeline.duration
            if not showing.any():  # e.g. one damping event at the run's last moment
                assert clip is None, (name, kind)
                continue
            visible = np.array(clip.tracks["visible"].values)
            scale = np.array(clip.tracks["scale"].values)[:, 0]
            assert np.allclose(np.array(clip.tracks["visible"].frames) / play.FPS, grid)
            assert np.array_equal(visible, showing), (name, kind)
            # Full size at an event, smaller as it fades, hidden and a speck at the end.
            assert not visible[-1] and scale[-1] <= 1e-3, (name, kind)
            assert clip.tracks["scale"].frames[-1] == pytest.approx(timeline.end * play.FPS)
            first = int(np.flatnonzero(showing)[0])
            assert scale[first] == pytest.approx(1 - (grid[first] - times.min()) / 0.25)
    # ur5_tool_spring: its last damping event is the run's last moment (Newton's method
    # finishes from there); the page opened on its end shows no flash.
    timeline = exported("ur5_tool_spring")[2].timeline
    assert timeline.events["damping"][-1] == pytest.approx(timeline.duration)


# --- the live server ------------------------------------------------------------------------


def _listening(port: int) -> list[str]:
    """Local addresses (hex, as in /proc/net/tcp) of the sockets listening on port."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.rsplit(":", 1)
            if state == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                found.append(address)
    return found


@pytest.fixture(scope="module")
def live():
    play = _play()
    viz = play.play(pinsettle.load_scene(ROBOTS / "ur5_tool_spring.toml"), live=True)
    yield viz
    viz.close()


def test_live_server_listens_on_loopback_only(live):
    from urllib.parse import urlparse

    url = urlparse(live.url)
    assert url.hostname == "127.0.0.1"
    assert _listening(url.port) == ["0100007F"]  # 127.0.0.1, and nothing else
    zmq = urlparse(live.window.server.zmq_url)
    assert zmq.hostname == "127.0.0.1" and _listening(zmq.port) == ["0100007F"]
    page = urllib.request.urlopen(live.url, timeout=10).read()
    assert b"meshcat" in page.lower()


# --- in a real browser -----------------------------------------------------------------------


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.fixture(scope="module")
def browser():
    path = _chromium()
    if path is None:
        if os.environ.get("PINSETTLE_REQUIRE_CHROMIUM") == "1":
            pytest.fail("Chromium is required here (PINSETTLE_REQUIRE_CHROMIUM=1) but not found")
        pytest.skip("headless Chromium not found (Debian: apt-get install chromium)")
    return path


def _run_chromium(browser: str, flags: list[str], url: str, tmp: Path) -> str | None:
    """Headless Chromium on url with a profile of its own; its stdout, or None when it did not
    finish within 90 s. Its whole process group is killed then: CI once saw a run on meshcat's
    plain page hang for 120 s while the same page had loaded in the run before."""
    profile = tmp / "chromium-profile"
    shutil.rmtree(profile, ignore_errors=True)
    args = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader"]
    args += ["--enable-unsafe-swiftshader", "--hide-scrollbars", "--window-size=800,600"]
    args += [f"--user-data-dir={profile}", *flags, url]
    proc = subprocess.Popen(
        args, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, start_new_session=True
    )
    try:
        out, _ = proc.communicate(timeout=90)
        return out
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        proc.communicate()
        return None


def screenshot(browser: str, url: str, path: Path, budget_ms: int = 4000) -> np.ndarray:
    """A screenshot of url (800x600) as an RGB array in [0, 1]; tried up to three times (a cold
    Chromium sometimes exits before writing, or hangs)."""
    for _ in range(3):
        if path.exists():
            path.unlink()
        flags = [f"--virtual-time-budget={budget_ms}", f"--screenshot={path}"]
        _run_chromium(browser, flags, url, path.parent)
        if path.exists():
            from matplotlib import image

            return image.imread(path)[:, :, :3]
    pytest.fail(f"Chromium wrote no screenshot of {url} in three tries")


def _hide_swatches(found: np.ndarray) -> None:
    """Leave the legend's swatches out of a mask of pixels: the overlay's left column (its
    lines of 19 px from the top, a dozen at most)."""
    found[:300, :40] = False


def _below_overlay(viz, h: int = 600) -> slice:
    """The rows of a screenshot below the overlay's box: its title, clock and counter and a
    line per entry of the legend, 19 px each (the view's top share the camera leaves to it)."""
    lines = 3 + len(viz._overlay()["legend"])
    return slice(max(h // 5, 20 + 19 * lines + 12), h)


def drawn_fraction(pixels: np.ndarray) -> float:
    """Share of the view below the overlay (the lower four fifths, its right edge left out)
    that is not background. The background is a vertical gradient: each row's colour is read
    at its right edge. The camera frames the whole run, so the final pose need not be in the
    middle: chain20, released horizontal, hangs at the right of the view (0.63% of this part
    drawn; 0.94% of the middle half, most of it outside). An empty view gives 0."""
    h, w, _ = pixels.shape
    below = pixels[h // 5 :, : w - 10]
    background = pixels[h // 5 :, w - 3 : w - 2]
    return float(np.mean(np.abs(below - background).max(axis=2) > 0.08))


@pytest.mark.parametrize("name", SCENES)
def test_screenshot_of_the_final_pose_shows_the_robot(name, exported, browser, tmp_path):
    scene, result, viz, html, plot = exported(name)
    end = screenshot(browser, html.as_uri() + "#end", tmp_path / "end.png")
    assert drawn_fraction(end) > 0.002, f"{name}: nothing drawn in the view"


PLAYED_SCENES = ["bistable_pendulum", "ur5", "panda_fingers_locked", "free_fall", "chain20"]


@pytest.mark.parametrize("name", PLAYED_SCENES)
def test_played_to_the_end_the_animation_holds_the_final_pose(name, exported, browser, tmp_path):
    scene, result, viz, html, plot = exported(name)
    end = screenshot(browser, html.as_uri() + "#end", tmp_path / "end.png")
    # Played to the end (the animation lasts viz.timeline.end s), it holds the same picture as
    # the page opened on its last frame.
    budget = int(1000 * viz.timeline.end) + 6000
    played = screenshot(browser, html.as_uri(), tmp_path / "played.png", budget)
    h = played.shape[0]
    below_overlay = _below_overlay(viz, h)  # the overlay's clock differs while it plays
    assert np.mean(np.abs(played[below_overlay] - end[below_overlay]) > 0.05) < 0.002
    # ... and that is not the start (except where the mechanism barely moves on screen).
    # The start is the page opened paused on its first frame: a short budget on the playing
    # page raced the animation (CI once caught it 0.0013 of the view away from the end).
    start = screenshot(browser, html.as_uri() + "#t=0", tmp_path / "start.png")
    if name in ("bistable_pendulum", "ur5", "chain20"):
        assert np.mean(np.abs(start[below_overlay] - end[below_overlay]) > 0.05) > 0.002


def test_live_page_shows_the_robot(live, browser, tmp_path):
    pixels = screenshot(browser, live.url, tmp_path / "live.png", 8000)
    assert drawn_fraction(pixels) > 0.002


def page_dom(browser: str, url: str, budget_ms: int, tmp: Path) -> str:
    """The page's DOM after ``budget_ms`` of (virtual) time, as headless Chromium prints it;
    tried up to three times."""
    for _ in range(3):
        out = _run_chromium(browser, [f"--virtual-time-budget={budget_ms}", "--dump-dom"], url, tmp)
        if out and "<html" in out:
            return out
    pytest.fail(f"Chromium printed no page for {url} in three tries")


def _overlay_text(dom: str) -> str:
    """The text the overlay shows (its elements' text, tags dropped)."""
    found = re.search(r'<div id="pinsettle-overlay"[^>]*>(.*?)</div>\s*<script', dom, re.S)
    assert found, "no overlay in the page"
    return re.sub(r"<[^>]+>", " ", found.group(1))


def _overlay_pixels(pixels: np.ndarray) -> int:
    """Dark (text) pixels where the overlay's box is (top left)."""
    return int(np.count_nonzero(pixels[12:90, 12:480].max(axis=2) < 0.35))


def _flash_pixels(pixels: np.ndarray) -> float:
    """Share of the view in the damping flash's translucent yellow, the legend's swatches
    (left of the overlay's text) left out."""
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    found = (r > 0.7) & (g > 0.55) & (r - b > 0.25) & (g - b > 0.12)
    _hide_swatches(found)
    return float(np.mean(found))


def test_screenshot_shows_the_damping_flash_then_not_on_the_final_pose(exported, browser, tmp_path):
    scene, result, viz, html, plot = exported("ur5_tool_spring")
    timeline = viz.timeline
    first, last = timeline.events["damping"][[0, -1]]
    assert last == pytest.approx(timeline.duration)  # an event at the run's last moment
    at = (first + 0.2 * _play().FLASH_SECONDS) * timeline.speed  # #t= is simulated time
    flash = screenshot(browser, f"{html.as_uri()}#t={at:.6g}", tmp_path / "flash.png")
    end = screenshot(browser, html.as_uri() + "#end", tmp_path / "end.png")
    # The ball at the centre of mass: some 0.3% of the view at the first event, none at the
    # end (the spring's orange is not counted: 0.01% of the view).
    assert _flash_pixels(flash) > 0.0015 and _flash_pixels(end) < 0.0005


def test_the_page_shows_every_entry_of_the_legend(exported, browser, tmp_path):
    scene, result, viz, html, plot = exported("fourbar_stop")
    legend = viz._overlay()["legend"]
    assert len(legend) >= 4  # loads, joint spring, loop, stop, damping flash
    dom = page_dom(browser, html.as_uri() + "#end", 2000, tmp_path)
    entries = re.findall(
        r'<div class="pinsettle-legend"><span class="pinsettle-swatch" '
        r'style="background: rgb\((\d+), (\d+), (\d+)\);"></span>(.*?)</div>',
        dom,
    )
    shown = [
        (f"#{int(r):02x}{int(g):02x}{int(b):02x}", html_lib.unescape(t)) for r, g, b, t in entries
    ]
    assert shown == [(entry["color"], entry["text"]) for entry in legend], dom[-3000:]


def test_live_page_has_the_overlay_of_the_static_page(live, browser, tmp_path):
    # The live page carries the static page's overlay: the same information, the same script.
    page = urllib.request.urlopen(live.url, timeout=10).read().decode("utf-8")
    static = live.html()
    for part in ('<div id="pinsettle-overlay">', "pinsettle-info", "function tick()"):
        assert part in page and part in static
    info = re.compile(r'id="pinsettle-info">(.*?)</script>', re.S)
    assert info.search(page).group(1) == info.search(static).group(1)
    # Playing in a browser: the title, the simulated time and speed, the counter. (Where it
    # has got to depends on how fast the scene came over the websocket: a loaded machine
    # once caught it before the end.)
    result, timeline = live.result, live.timeline
    text = " ".join(_overlay_text(page_dom(browser, live.url, 8000, tmp_path)).split())
    assert text.startswith(f"ur5_tool_spring {result.status}: {result.steps} steps")
    label = re.escape(_play().speed_label(timeline.speed))
    clock = re.search(rf"t = (\d+\.\d{{3}}) s simulated, played {label}", text)
    assert clock and 0 <= float(clock.group(1)) <= timeline.duration * timeline.speed + 1e-3
    n = len(timeline.events["damping"])
    counter = re.search(rf"damping events (\d+) / {n}\b", text)
    assert n == result.peaks > 0 and counter and int(counter.group(1)) <= n, text
    # ... and on screen: the overlay's text where meshcat's own page (no overlay) has none.
    ours = screenshot(browser, live.url, tmp_path / "live.png", 8000)
    plain = screenshot(browser, live.url.replace("/pinsettle/", "/static/"), tmp_path / "m.png")
    assert _overlay_pixels(ours) > 300 and _overlay_pixels(plain) == 0


# --- impacts on a stop: the link flashes ------------------------------------------------------


def _pendulum_on_stops():
    """The pendulum released at 0.45 rad between stops at -0.3 and 0.5 rad: with kt = 0.9 (the
    fixture) it swings through the bottom, hits the lower stop, and settles hanging down
    between them (kt = 0, stopped dead at the bottom, never reaches a stop)."""
    scene = pinsettle.Scene.from_urdf(ROBOTS / "pendulum.urdf")
    return scene.set_limit("hinge", lower=-0.3, upper=0.5).set_start(hinge=0.45)


@pytest.fixture(scope="module")
def impacts(tmp_path_factory):
    play = _play()
    scene = _pendulum_on_stops()
    result = pinsettle.solve(scene, kt=0.9, **play.TRACE_SETTINGS)
    html = tmp_path_factory.mktemp("impacts") / "impacts.html"
    viz = play.play(scene, result, html=html, live=False)
    return scene, result, viz, html


def test_impacts_are_traced_with_their_joint(impacts):
    scene, result, viz, html = impacts
    trace = result.trace
    kinds = np.array(trace.event_kind)
    hinge = scene.model.getJointId("hinge")
    assert np.count_nonzero(kinds == "impact") >= 1
    assert trace.event_joint.shape == kinds.shape
    assert np.all(trace.event_joint[kinds == "impact"] == hinge)
    assert np.all(trace.event_joint[kinds != "impact"] == -1)
    # An impact in step k (from the state of step k to that of k + 1): the hinge was above
    # its lower stop at k, and is on it at k + 1, the event's time.
    assert trace.stride == 1
    hits = kinds == "impact"
    for step, at in zip(trace.event_step[hits], trace.event_time[hits], strict=True):
        k = int(np.searchsorted(trace.step, step))
        assert trace.step[k] == step and trace.step[k + 1] == step + 1
        assert trace.q[k, 0] > -0.3
        assert trace.q[k + 1, 0] == pytest.approx(-0.3, abs=1e-12)
        assert trace.time[k + 1] == pytest.approx(at, rel=1e-12)
    assert result.converged and abs(result.q[0]) < 1e-6 and not result.at_limit


def test_impacts_flash_the_link_that_hit(impacts):
    scene, result, viz, html = impacts
    play = _play()
    timeline = viz.timeline
    trace = result.trace
    kinds = np.array(trace.event_kind)
    hinge = scene.model.getJointId("hinge")
    t0 = trace.time[0]
    expected = np.sort((trace.event_time[kinds == "impact"] - t0) / timeline.speed)
    assert np.allclose(timeline.events["impact"], expected)
    assert np.all(timeline.impact_joints == hinge)
    # The link the hinge carries: hidden while it flashes, its copy in the impact colour shown
    # instead, from each impact for FLASH_SECONDS; itself again at the end.
    grid = timeline.frame_times()
    since = grid[:, None] - expected[None, :]
    flashing = np.any((since >= 0) & (since < play.FLASH_SECONDS), axis=1)
    assert flashing.any() and not flashing[-1]
    clips = {str(path.lower()): clip for path, clip in viz.animation.clips.items()}
    links = [obj for obj in viz.visual_model.geometryObjects if obj.parentJoint == hinge]
    assert links
    for obj in links:
        base = f"/meshcat/pinsettle/pinocchio/visuals/{obj.name}"
        shown = clips[base].tracks["visible"]
        flash = clips[base + "_impact"].tracks["visible"]
        assert np.allclose(np.array(shown.frames) / play.FPS, grid)
        assert np.array_equal(shown.values, ~flashing)
        assert np.array_equal(flash.values, flashing)
        # The copy moves with the link.
        position = clips[base].tracks["position"].values
        assert np.allclose(clips[base + "_impact"].tracks["position"].values, position)
    others = [obj for obj in viz.visual_model.geometryObjects if obj.parentJoint != hinge]
    for obj in others:
        assert "visible" not in clips[f"/meshcat/pinsettle/pinocchio/visuals/{obj.name}"].tracks
    # The energy plot's legend names the joint; the page counts the impacts.
    assert play._impact_names(result, "impact") == ": hinge"
    assert '"impact": [' in html.read_text(encoding="utf-8")


def test_the_impact_flash_is_in_the_legend(impacts):
    scene, result, viz, html = impacts
    assert any(path.endswith("_impact") for path in _drawn_marks(viz))
    _check_legend_covers_the_marks(viz, html.read_text("utf-8"))
    texts = [entry["text"] for entry in viz._overlay()["legend"]]
    assert any(t.startswith("link flashing pink-red") and t.endswith("(hinge)") for t in texts)


def test_impact_joints_of_a_scene_with_locked_joints_are_the_full_models():
    # joint1 locked: the solver's model has joint2 and joint3 as its joints 1 and 2.
    scene = pinsettle.Scene.from_urdf(ROBOTS / "planar_3link.urdf").lock("joint1")
    scene.set_limit("joint3", lower=-0.2, upper=0.2).set_start(joint1=0.3, joint2=1.2)
    result = pinsettle.solve(scene, **_play().TRACE_SETTINGS)
    trace = result.trace
    impacts = np.array(trace.event_kind) == "impact"
    assert impacts.any()
    joint3 = scene.model.getJointId("joint3")
    assert joint3 == 3 and np.all(trace.event_joint[impacts] == joint3)
    iq = scene.model.idx_qs[joint3]
    for step in trace.event_step[impacts]:
        k = int(np.searchsorted(trace.step, step + 1))
        assert trace.step[k] == step + 1
        assert abs(trace.q[k, iq]) == pytest.approx(0.2, abs=1e-12)


def _impact_pixels(pixels: np.ndarray) -> float:
    """Share of the view in the impact colour (a lit pink-red: red high, green low), the
    legend's swatches (left of the overlay's text) left out."""
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    found = (r > 0.55) & (g < 0.3) & (b > 0.15) & (b < 0.6)
    _hide_swatches(found)
    return float(np.mean(found))


def test_screenshot_shows_the_flash_at_an_impact(impacts, browser, tmp_path):
    scene, result, viz, html = impacts
    at = float(viz.timeline.events["impact"][0]) + 0.3 * _play().FLASH_SECONDS
    speed = viz.timeline.speed  # #t= is simulated time; the events are in playback seconds
    flash = screenshot(browser, f"{html.as_uri()}#t={at * speed:.6g}", tmp_path / "flash.png")
    end = screenshot(browser, html.as_uri() + "#end", tmp_path / "end.png")
    before_t = max(at - 0.35, 0) * speed
    before = screenshot(browser, f"{html.as_uri()}#t={before_t:.6g}", tmp_path / "b.png")
    assert _impact_pixels(flash) > 0.001, "no flash at the impact"
    assert _impact_pixels(end) == 0 and _impact_pixels(before) == 0


# --- users' meshes: STL files without normals or colour -------------------------------------


def _ur5_with_stl_visuals(folder: Path, material: str = "") -> Path:
    """A scene of the UR5 of example-robot-data whose visuals are its collision STL files (with
    zero normals in the file, as many exporters write them); ``material`` (a URDF <material>
    element) is put on the upper arm's visual."""
    urdf = Path(pinsettle.robot_urdf("ur5")).read_text(encoding="utf-8")
    urdf = re.sub(r"meshes/ur5/visual/(\w+)\.dae", r"meshes/ur5/collision/\1.stl", urdf)
    assert urdf.count("collision/upperarm.stl") == 2  # the visual and the collision
    if material:
        at = urdf.index("collision/upperarm.stl")
        at = urdf.index("</visual>", urdf.rfind("<visual>", 0, at))
        urdf = urdf[:at] + material + urdf[at:]
    (folder / "ur5_stl.urdf").write_text(urdf, encoding="utf-8")
    (folder / "ur5_stl.toml").write_text('[model]\nurdf = "ur5_stl.urdf"\n', encoding="utf-8")
    return folder / "ur5_stl.toml"


def _cube_triangles() -> np.ndarray:
    """The 12 triangles of the cube [0, 1]^3, counter-clockwise seen from outside."""
    corners = np.array([[i >> 2 & 1, i >> 1 & 1, i & 1] for i in range(8)], dtype=float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    triangles = []
    for a, b, c, d in quads:
        triangles += [corners[[a, b, c]], corners[[a, c, d]]]
    return np.array(triangles)


def test_read_stl_binary_and_ascii_with_outward_normals(tmp_path):
    play = _play()
    triangles = _cube_triangles()
    binary = tmp_path / "cube_binary.stl"
    records = b"".join(
        np.zeros(3, "<f4").tobytes() + t.astype("<f4").tobytes() + b"\0\0" for t in triangles
    )
    binary.write_bytes(
        b"solid but binary".ljust(80, b" ") + len(triangles).to_bytes(4, "little") + records
    )
    ascii_stl = tmp_path / "cube_ascii.stl"
    facets = "".join(
        "facet normal 0 0 0\n outer loop\n"
        + "".join(f"  vertex {x:g} {y:g} {z:g}\n" for x, y, z in t)
        + " endloop\nendfacet\n"
        for t in triangles
    )
    ascii_stl.write_text(f"solid cube\n{facets}endsolid cube\n", encoding="ascii")
    for path in (binary, ascii_stl):
        vertices, faces, normals = play.read_stl(path)
        assert np.array_equal(vertices, triangles.reshape(-1, 3))
        assert np.array_equal(vertices[faces], triangles)
        # Unit normals pointing away from the cube's centre, the same for a face's 3 vertices.
        assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
        outward = triangles.mean(axis=1) - 0.5
        per_face = normals.reshape(-1, 3, 3)
        assert np.allclose(per_face, per_face[:, :1])
        assert np.all(np.einsum("ij,ij->i", per_face[:, 0], outward) > 0.4)
    broken = tmp_path / "broken.stl"
    broken.write_text("solid x\nfacet normal 0 0 1\n outer loop\n  vertex 0 0\n", encoding="ascii")
    with pytest.raises(ValueError, match="broken.stl: not a readable STL file"):
        play.read_stl(broken)


def test_stl_meshes_are_lit_in_their_urdf_colour_or_grey(browser, tmp_path):
    play = _play()
    red = '<material name="red"><color rgba="0.85 0.1 0.1 1"/></material>'
    scene = pinsettle.load_scene(_ur5_with_stl_visuals(tmp_path, red))
    viz = play.play(scene, html=tmp_path / "ur5_stl.html", live=False)
    colors = {obj.name: tuple(obj.meshColor) for obj in viz.visual_model.geometryObjects}
    assert colors["upper_arm_link_0"] == pytest.approx((0.85, 0.1, 0.1, 1.0))
    assert all(c[:3] != pytest.approx((0.9, 0.9, 0.9)) for c in colors.values())
    pixels = screenshot(browser, (tmp_path / "ur5_stl.html").as_uri() + "#end", tmp_path / "s.png")
    h, w, _ = pixels.shape
    middle = pixels[h // 5 :, w // 4 : 3 * w // 4]  # below the overlay
    background = pixels[h // 5 :, w - 3 : w - 2]
    robot = middle[np.abs(middle - background).max(axis=2) > 0.08]
    assert robot.shape[0] > 0.01 * middle.shape[0] * middle.shape[1], "no robot drawn"
    # Lit, not a silhouette: few dark pixels, and the shading varies over the surface.
    brightness = robot.max(axis=1)
    assert np.mean(brightness < 0.15) < 0.02, f"{np.mean(brightness < 0.15):.1%} near black"
    assert np.median(brightness) > 0.35
    assert np.ptp(np.percentile(brightness, [10, 90])) > 0.05
    # The upper arm red, the rest a neutral grey.
    r, g, b = robot.T
    red_share = np.mean((r > 0.45) & (g < 0.3) & (b < 0.3))
    grey_share = np.mean((np.abs(r - g) < 0.06) & (np.abs(g - b) < 0.08) & (brightness > 0.3))
    assert red_share > 0.1 and grey_share > 0.3, (red_share, grey_share)


def test_notebook_api_returns_pinocchios_visualizer():
    from pinocchio.visualize import MeshcatVisualizer

    scene = pinsettle.load_scene(ROBOTS / "pendulum.toml")
    result = pinsettle.solve(scene, **pinsettle.play.TRACE_SETTINGS)
    viz = pinsettle.play(scene, result, live=False)
    assert isinstance(viz, MeshcatVisualizer)
    assert viz.result is result and viz.url is None  # live=False: no server
    assert viz.html().startswith("<!DOCTYPE html>")


# --- short settles: slow motion ---------------------------------------------------------------

SHORT_SETTLES = ["fourbar", "slider_crank", "parallel_gripper"]


@pytest.mark.parametrize("name", SHORT_SETTLES)
def test_a_short_settle_plays_in_slow_motion(name, exported):
    play = _play()
    scene, result, viz, html, plot = exported(name)
    assert result.sim_time < 0.5  # settles in a few frames of real time
    timeline = viz.timeline
    # Slowed down so that it lasts MIN_PLAYBACK_SECONDS (>= 2 s) of playback.
    assert timeline.duration == pytest.approx(play.MIN_PLAYBACK_SECONDS) and timeline.duration >= 2
    assert timeline.speed == pytest.approx(result.sim_time / play.MIN_PLAYBACK_SECONDS)
    # A keyframe at least every 1.5 / FPS s of the motion, the last at its end (no hold).
    steps = np.diff(timeline.times)
    assert steps.max() <= 1.5 / play.FPS + 1e-12 and timeline.end == timeline.duration
    # The recorded configurations are among the keyframes, at their time (simulated time /
    # speed), then the final pose (result.q, the last sample polished); those between are on
    # Pinocchio's interpolation of their neighbours.
    trace = result.trace
    assert np.allclose(timeline.q[-1], result.q)
    kept = trace.time < result.sim_time
    for t, q in zip(trace.time[kept], trace.q[kept], strict=True):
        k = int(np.argmin(np.abs(timeline.times - (t - trace.time[0]) / timeline.speed)))
        assert np.allclose(timeline.q[k], q, atol=1e-12)
    k = 1
    recorded = np.isclose(
        timeline.times[:, None], (trace.time[kept] - trace.time[0]) / timeline.speed
    )
    while recorded[k].any():
        k += 1
    before, after = k - 1, k + 1
    while not recorded[after].any() and timeline.times[after] < timeline.duration:
        after += 1
    u = (timeline.times[k] - timeline.times[before]) / (
        timeline.times[after] - timeline.times[before]
    )
    expected = pinocchio.interpolate(scene.model, timeline.q[before], timeline.q[after], u)
    assert np.allclose(timeline.q[k], expected, atol=1e-12)
    # The page says the factor.
    assert play.speed_label(timeline.speed) == f"x{timeline.speed:.3g} (slow motion)"
    assert f'"speed_label": "x{timeline.speed:.3g} (slow motion)"' in html.read_text("utf-8")


def test_speed_overrides_the_slow_motion(tmp_path):
    play = _play()
    scene = pinsettle.load_scene(ROBOTS / "fourbar.toml")
    result = pinsettle.solve(scene, **play.TRACE_SETTINGS)
    viz = play.play(scene, result, speed=1.0, live=False)
    assert viz.timeline.speed == 1.0
    assert viz.timeline.duration == pytest.approx(result.sim_time)
    assert play.speed_label(1.0) == "x1 (real time)" and play.speed_label(4.2) == "x4.2 (sped up)"
    proc = subprocess.run(
        [sys.executable, "-m", "pinsettle", "play", "fourbar", "--no-open", "--speed", "0.1"]
        + ["--html", str(tmp_path / "f.html")],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"in {result.sim_time / 0.1:.3g} s (speed x0.1)" in proc.stdout


def test_screenshot_of_a_short_settle_moves_between_start_and_end(exported, browser, tmp_path):
    scene, result, viz, html, plot = exported("fourbar")
    h = 600
    below = slice(h // 5, h)  # below the overlay
    shots = {
        t: screenshot(browser, f"{html.as_uri()}#t={t:.6g}", tmp_path / f"{t}.png")[below]
        for t in (0, 0.5 * result.sim_time, result.sim_time)  # simulated time
    }
    start, middle, end = shots.values()

    def changed(a: np.ndarray, b: np.ndarray) -> float:
        return float(np.mean(np.abs(a - b).max(axis=2) > 0.05))

    # Half-way through the playback the four-bar is neither where it started nor at rest.
    assert changed(start, middle) > 0.002 and changed(middle, end) > 0.002, (
        changed(start, middle),
        changed(middle, end),
    )


@pytest.mark.parametrize("name", ["fourbar", "ur5"])
def test_the_time_slider_reads_simulated_time(name, exported, browser, tmp_path):
    # meshcat's Animations folder: its time slider runs from 0 to the simulated time of the
    # settle (no hold after it), its timeScale is the playback's speed, and the page opened
    # on its end or half-way (#t=, simulated seconds) shows that time on the slider. The
    # page is read by a script added to a copy of it (dat.gui keeps the values in input
    # properties, not in the DOM; a playing page is not read: how far headless Chromium's
    # virtual time gets varies from run to run).
    scene, result, viz, html, plot = exported(name)
    probe = """<pre id="probe"></pre><script>(function read() {
      const a = viewer.animator, gui = a.folder.__folders["default"].__controllers;
      const slider = gui.find((c) => c.property === "time");
      const scale = gui.find((c) => c.property === "timeScale");
      document.getElementById("probe").textContent = JSON.stringify({time: a.time,
        max: slider.__max, speed: a.mixer.timeScale, playing: a.playing,
        shown: Number(slider.__li.querySelector("input").value),
        speed_shown: Number(scale.__input.value)});
      requestAnimationFrame(read);
    })();</script></body>"""
    head, _, tail = html.read_text("utf-8").rpartition("</body>")
    copy = tmp_path / "probe.html"
    copy.write_text(head + probe + tail, encoding="utf-8")
    sim_time = viz.timeline.sim_time  # the trace's first sample to the end
    assert sim_time == pytest.approx(result.sim_time, abs=1e-12)
    for at in (sim_time, 0.5 * sim_time):
        url = copy.as_uri() + ("#end" if at == sim_time else f"#t={at!r}")
        found = re.search(
            r'<pre id="probe">(.*?)</pre>', page_dom(browser, url, 2000, tmp_path), re.S
        )
        assert found and found.group(1), url
        read = json.loads(html_lib.unescape(found.group(1)))
        assert read["max"] == pytest.approx(sim_time, rel=1e-6)  # three.js keeps float32
        assert read["speed"] == pytest.approx(viz.timeline.speed, rel=1e-12)
        assert read["speed_shown"] == pytest.approx(viz.timeline.speed, abs=0.01)
        assert not read["playing"] and read["time"] == pytest.approx(at, rel=1e-6)
        assert read["shown"] == pytest.approx(at, abs=1e-3)


# --- what holds a rest: loads, loop closure points, stop reactions ------------------------------


def _clips(viz) -> dict:
    return {str(path.lower()): clip for path, clip in viz.animation.clips.items()}


def _rotate(quaternion_xyzw, vector) -> np.ndarray:
    x, y, z, w = quaternion_xyzw
    return pinocchio.Quaternion(w, x, y, z).matrix() @ np.asarray(vector, dtype=float)


def test_a_point_load_is_an_arrow_from_its_point_along_its_force(exported):
    scene, result, viz, html, plot = exported("fourbar_stop")
    (load,) = scene.loads  # 10 N down at 0.2 m along the coupler
    model, data = scene.model, scene.model.createData()
    frame = model.getFrameId(load.frame)
    force = np.asarray(load.force)
    clip = _clips(viz)["/meshcat/pinsettle/forces/load_0"]
    position, quaternion = clip.tracks["position"].values, clip.tracks["quaternion"].values
    scale = clip.tracks["scale"].values
    assert len(position) == viz.timeline.times.size
    for q, at, turn, s in zip(viz.timeline.q, position, quaternion, scale, strict=True):
        pinocchio.framesForwardKinematics(model, data, q)
        # Its tail on the load's point (Pinocchio's placement of the frame), its axis (the
        # arrow's +y) along the world-aligned force, its length constant.
        assert np.allclose(at, data.oMf[frame].act(np.asarray(load.point)), atol=1e-12)
        assert np.allclose(_rotate(turn, [0, 1, 0]), force / np.linalg.norm(force), atol=1e-9)
        assert s[1] == pytest.approx(scale[0][1]) and s[1] > 0
    # The last keyframe is the final pose.
    pinocchio.framesForwardKinematics(model, data, result.q)
    assert np.allclose(position[-1], data.oMf[frame].act(np.asarray(load.point)), atol=1e-12)


def test_loop_closure_points_follow_their_bodies_and_meet_at_rest(exported):
    scene, result, viz, html, plot = exported("fourbar")
    (loop,) = scene.loops
    model, data = scene.model, scene.model.createData()
    clips = _clips(viz)
    a = clips["/meshcat/pinsettle/forces/loop_0_a"].tracks["position"].values
    b = clips["/meshcat/pinsettle/forces/loop_0_b"].tracks["position"].values
    for q, at_a, at_b in zip(viz.timeline.q, a, b, strict=True):
        pinocchio.framesForwardKinematics(model, data, q)
        fa, fb = model.getFrameId(loop.a_frame), model.getFrameId(loop.b_frame)
        assert np.allclose(at_a, data.oMf[fa].act(np.asarray(loop.a_point)), atol=1e-12)
        assert np.allclose(at_b, data.oMf[fb].act(np.asarray(loop.b_point)), atol=1e-12)
    assert np.linalg.norm(np.subtract(a[-1], b[-1])) < 1e-8  # closed at rest


def test_a_stop_reaction_is_an_arrow_at_the_end(exported):
    import umsgpack
    from meshcat.servers.tree import find_node

    play = _play()
    scene, result, viz, html, plot = exported("fourbar_stop")
    assert result.at_limit == {"rocker_joint": "upper"}
    # The arrow: at the rocker's joint (Pinocchio's placement at rest), along its axis (y of
    # the joint's frame), pointing down the joint's angle (an upper stop pushes q down).
    model, data = scene.model, scene.model.createData()
    joint = model.getJointId("rocker_joint")
    assert model.joints[joint].shortname() == "JointModelRY"
    pinocchio.forwardKinematics(model, data, result.q)
    axis = data.oMi[joint].rotation[:, 1]
    node = find_node(viz.window.tree, ["meshcat", "pinsettle", "forces", "stop_0"])
    matrix = np.array(umsgpack.unpackb(node.transform)["matrix"]).reshape(4, 4).T
    assert np.allclose(matrix[:3, 3], data.oMi[joint].translation, atol=1e-12)
    direction = matrix[:3, 1] / np.linalg.norm(matrix[:3, 1])
    assert np.allclose(direction, -axis, atol=1e-9)
    # Shown once the motion is over, hidden before.
    visible = _clips(viz)["/meshcat/pinsettle/forces/stop_0"].tracks["visible"]
    assert visible.values == [False, False, True]
    assert visible.frames[-1] == pytest.approx(viz.timeline.duration * play.FPS)
    # The legend says what each mark is, with the reaction's value.
    legend = viz._overlay()["legend"]
    texts = " | ".join(mark["text"] for mark in legend)
    assert "arrow: load" in texts and "forces 10 N on coupler" in texts
    assert "joint spring (crank_joint k = 4)" in texts
    assert "loop closure points" in texts
    reaction = result.limit_reactions["rocker_joint"]
    assert "stop reaction" in texts and f"rocker_joint {reaction:.3g} N m" in texts
    assert '"legend": [' in html.read_text("utf-8")


def _color_pixels(pixels: np.ndarray, color: int) -> int:
    """Pixels of the flat colour ``color``, the legend's swatches (left of the overlay's text)
    left out."""
    rgb = np.array([(color >> 16) & 255, (color >> 8) & 255, color & 255]) / 255
    found = np.abs(pixels - rgb).max(axis=2) < 0.03
    _hide_swatches(found)
    return int(np.count_nonzero(found))


def test_screenshot_shows_the_load_the_loop_and_the_stop_reaction(exported, browser, tmp_path):
    forces = importlib.import_module("pinsettle._play_forces")
    scene, result, viz, html, plot = exported("fourbar_stop")
    end = screenshot(browser, html.as_uri() + "#end", tmp_path / "end.png")
    at = viz.timeline.speed  # 1 s into the playback, in simulated time
    moving = screenshot(browser, f"{html.as_uri()}#t={at:.6g}", tmp_path / "moving.png")
    for color in (forces.LOAD_COLOR, forces.LOOP_COLOR):
        assert _color_pixels(end, color) > 200 and _color_pixels(moving, color) > 200
    assert _color_pixels(end, forces.STOP_COLOR) > 200
    assert _color_pixels(moving, forces.STOP_COLOR) == 0


def _joint_axis_world(model, data, joint: int) -> np.ndarray:
    """A revolute or prismatic joint's axis in the world, from its type (…X, …Y, …Z) and
    Pinocchio's placement of the joint."""
    letter = model.joints[joint].shortname()[-1]
    return data.oMi[joint].rotation[:, "XYZ".index(letter)]


def test_a_joint_load_is_a_double_arrow_along_its_axis_and_a_joint_spring_a_coil(exported):
    from meshcat.servers.tree import find_node

    scene, result, viz, html, plot = exported("slider_crank")
    model, data = scene.model, scene.model.createData()
    crank, slider = model.getJointId("crank_joint"), model.getJointId("slider_joint")
    assert model.joints[crank].shortname() == "JointModelRY"
    assert model.joints[slider].shortname() == "JointModelPX"
    clips = _clips(viz)
    load = clips["/meshcat/pinsettle/forces/load_0"].tracks
    coil = clips["/meshcat/pinsettle/forces/joint_spring_0"].tracks
    for k, q in enumerate(viz.timeline.q):
        pinocchio.forwardKinematics(model, data, q)
        # The 0.5 N m effort on the crank: at the crank's joint, along +its axis (right-hand
        # rule: the effort is positive).
        assert np.allclose(load["position"].values[k], data.oMi[crank].translation, atol=1e-12)
        pointing = _rotate(load["quaternion"].values[k], [0, 1, 0])
        assert np.allclose(pointing, _joint_axis_world(model, data, crank), atol=1e-9)
        # The slider's spring: a coil along the slider's direction, centred on its joint.
        axis = _joint_axis_world(model, data, slider)
        along = _rotate(coil["quaternion"].values[k], [0, 0, 1])
        assert np.allclose(along, axis, atol=1e-9)
        middle = np.asarray(coil["position"].values[k]) + 0.5 * coil["scale"].values[k][2] * axis
        assert np.allclose(middle, data.oMi[slider].translation, atol=1e-12)
    # A torque has two heads, a force one.
    tree = viz.window.tree
    assert find_node(tree, ["meshcat", "pinsettle", "forces", "load_0", "head_1"]).object
    legend = " | ".join(mark["text"] for mark in viz._overlay()["legend"])
    assert "double head: torques 0.5 N m at crank_joint" in legend
    assert "joint spring (slider_joint k = 200)" in legend


def test_the_camera_frames_everything_below_the_overlay():
    animation = importlib.import_module("pinsettle._play_animation")
    rng = np.random.default_rng(4)
    points = rng.normal(size=(200, 3)) * [0.3, 0.2, 0.5] + [1.0, -2.0, 0.5]
    for top in (0.0, 0.25):
        target, distance, size = animation._camera_fit(points, top)
        # Project as meshcat's camera does: at distance along _CAMERA_DIRECTION from the
        # target, looking at it, z up, the vertical field of view _CAMERA_FOV, a 4:3 view.
        back = animation._CAMERA_DIRECTION / np.linalg.norm(animation._CAMERA_DIRECTION)
        right = np.cross(-back, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, -back)
        rel = points - (target + distance * back)
        depth = rel @ -back
        tan = np.tan(np.radians(animation._CAMERA_FOV) / 2)
        y, x = (rel @ up) / (depth * tan), (rel @ right) / (depth * tan * 4 / 3)
        # Every point in view, none in the top share left to the overlay; the fit is tight.
        assert np.all(depth > 0) and np.all(np.abs(x) <= 1) and y.min() >= -1
        assert y.max() <= 1 - 2 * top and y.max() > 1 - 2 * top - 0.3


def test_a_point_torque_has_two_heads_and_a_free_bodys_wrench_is_named_as_not_drawn(tmp_path):
    from meshcat.servers.tree import find_node

    play = _play()
    scene = pinsettle.Scene.from_urdf(ROBOTS / "pendulum.urdf").set_start(hinge=0.3)
    scene.add_load(frame="arm", point=(0.0, 0.0, -0.5), force=(2.0, 0.0, 0.0))
    scene.add_load(frame="arm", point=(0.0, 0.0, -0.5), torque=(0.0, 0.5, 0.0))
    viz = play.play(scene, live=False)
    clips, tree = _clips(viz), viz.window.tree
    model, data = scene.model, scene.model.createData()
    pinocchio.framesForwardKinematics(model, data, viz.result.q)
    at = data.oMf[model.getFrameId("arm")].act(np.array([0.0, 0.0, -0.5]))
    for i, (vector, heads) in enumerate((([1, 0, 0], 1), ([0, 1, 0], 2))):
        tracks = clips[f"/meshcat/pinsettle/forces/load_{i}"].tracks
        assert np.allclose(tracks["position"].values[-1], at, atol=1e-12)
        assert np.allclose(_rotate(tracks["quaternion"].values[-1], [0, 1, 0]), vector, atol=1e-9)
        node = find_node(tree, ["meshcat", "pinsettle", "forces", f"load_{i}"])
        assert sorted(k for k in node if k.startswith("head_")) == [
            f"head_{h}" for h in range(heads)
        ]
    legend = " | ".join(mark["text"] for mark in viz._overlay()["legend"])
    assert "forces 2 N on arm; double head: torques 0.5 N m on arm" in legend
    # A joint load on a free body's root (6 entries): no one axis to draw it along; said.
    free = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    free.add_load(free.model.names[1], [0.0, 0.0, 9.81, 0.0, 0.0, 0.0])
    legend = " | ".join(m["text"] for m in play.play(free, live=False)._overlay()["legend"])
    assert f"not drawn: the effort on {free.model.names[1]}" in legend


def test_a_loop_reaction_balances_the_rocker_and_is_an_arrow_at_the_end(exported):
    forces = importlib.import_module("pinsettle._play_forces")
    play = _play()
    scene, result, viz, html, plot = exported("fourbar")
    (loop,) = scene.loops  # a: the coupler's end, b: the rocker's
    ((at, force),) = forces.loop_reactions(scene, result)
    model, data = scene.model, scene.model.createData()
    pinocchio.framesForwardKinematics(model, data, result.q)
    a = data.oMf[model.getFrameId(loop.a_frame)].act(np.asarray(loop.a_point))
    assert np.allclose(at, a, atol=1e-12)
    # The rocker alone (hinged to the ground, nothing else on it but its weight and the
    # closure's force -force at b): its moments about its hinge balance. Its weight's moment
    # is Pinocchio's generalized gravity of its joint (the rocker is a leaf of the tree).
    rocker = model.getJointId("rocker_joint")
    assert model.parents[rocker] == 0 and [load.frame for load in scene.loads] == ["coupler"]
    assert [spring.joint for spring in scene.joint_springs] == ["crank_joint"]
    gravity = pinocchio.computeGeneralizedGravity(model, data, result.q)[model.idx_vs[rocker]]
    axis = _joint_axis_world(model, data, rocker)
    moment = axis @ np.cross(a - data.oMi[rocker].translation, -force)
    assert moment == pytest.approx(gravity, rel=1e-6, abs=1e-9)
    assert abs(force[1]) < 1e-12  # planar: no out-of-plane force
    # Drawn at a along the force, once the motion is over.
    import umsgpack
    from meshcat.servers.tree import find_node

    node = find_node(viz.window.tree, ["meshcat", "pinsettle", "forces", "loop_reaction_0"])
    matrix = np.array(umsgpack.unpackb(node.transform)["matrix"]).reshape(4, 4).T
    assert np.allclose(matrix[:3, 3], a, atol=1e-12)
    direction = matrix[:3, 1] / np.linalg.norm(matrix[:3, 1])
    assert np.allclose(direction, force / np.linalg.norm(force), atol=1e-9)
    visible = _clips(viz)["/meshcat/pinsettle/forces/loop_reaction_0"].tracks["visible"]
    assert visible.values == [False, False, True]
    assert visible.frames[-1] == pytest.approx(viz.timeline.duration * play.FPS)
    legend = " | ".join(mark["text"] for mark in viz._overlay()["legend"])
    assert f"force on a (loop 1 {np.linalg.norm(force):.3g} N)" in legend
