"""Playback of ground contacts: the grounds' slabs, the contact points following their bodies and
the contact forces at the end, read from what would be sent to meshcat (the window's scene tree
and the animation's clips), checked against Pinocchio's frame placements, the scene's grounds
and the solve's ``Result.contacts``; and none of it, not even its module, for a scene without
grounds.

Like tests/test_play.py, these tests skip without the viz extra or Chromium, except where
PINSETTLE_REQUIRE_CHROMIUM=1, where their absence fails.
"""

from __future__ import annotations

import dataclasses
import importlib
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio
import pinsettle
import pytest
from test_play import _color_pixels, browser, screenshot, viz_extra  # noqa: F401  (fixtures)

ROBOTS = Path(__file__).resolve().parents[1] / "robots"
ROOT = ("meshcat", "pinsettle", "contacts")


def _play() -> Any:
    return importlib.import_module("pinsettle.play")


def _contacts_module() -> Any:
    return importlib.import_module("pinsettle._play_contacts")


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    """Library scenes with grounds, solved and played to a static page, once each."""
    folder = tmp_path_factory.mktemp("play_contacts")
    cache: dict[str, Any] = {}

    def get(name: str):
        if name not in cache:
            play = _play()
            scene = pinsettle.load_scene(ROBOTS / f"{name}.toml")
            result = pinsettle.solve(scene, **play.TRACE_SETTINGS)
            html = folder / f"{name}.html"
            cache[name] = (scene, result, play.play(scene, result, html=html, live=False), html)
        return cache[name]

    return get


def _node(viz: Any, name: str) -> Any:
    from meshcat.servers.tree import find_node

    return find_node(viz.window.tree, [*ROOT, name])


def _children(viz: Any) -> list[str]:
    from meshcat.servers.tree import find_node

    parent = find_node(viz.window.tree, list(ROOT[:2]))  # a defaultdict: read, not indexed
    return sorted(parent["contacts"]) if "contacts" in parent else []


def _object(node: Any) -> dict[str, Any]:
    """The geometry and material of the object set on ``node`` (as sent to meshcat)."""
    import umsgpack

    sent = umsgpack.unpackb(node.object)["object"]
    return {"geometry": sent["geometries"][0], "material": sent["materials"][0]}


def _matrix(node: Any) -> np.ndarray:
    import umsgpack

    return np.array(umsgpack.unpackb(node.transform)["matrix"]).reshape(4, 4).T


def _clip(viz: Any, name: str) -> Any:
    clips = {str(path.lower()): clip for path, clip in viz.animation.clips.items()}
    return clips["/meshcat/pinsettle/contacts/" + name]


def _world_points(scene: Any, q: np.ndarray) -> np.ndarray:
    """Each contact's centre in the world at q: Pinocchio's placement of its frame."""
    model = scene.model
    data = model.createData()
    pinocchio.framesForwardKinematics(model, data, q)
    return np.array(
        [data.oMf[model.getFrameId(c.frame)].act(np.asarray(c.point)) for c in scene.contacts]
    )


# --- the contact points -------------------------------------------------------------------------


def test_the_box_on_the_floor_has_four_markers_on_its_corners(played):
    scene, result, viz, _ = played("box_on_floor")
    assert len(scene.contacts) == 4
    # The rest pose's bottom corners, from the box's size (0.2 x 0.1 x 0.1 m, free_body.urdf)
    # and Pinocchio's placement of the body: on the floor (z = 0, its gap closed).
    model, data = scene.model, scene.model.createData()
    pinocchio.framesForwardKinematics(model, data, result.q)
    body = data.oMf[model.getFrameId("body")]
    corners = [body.act(np.array([x, y, -0.05])) for x in (-0.1, 0.1) for y in (-0.05, 0.05)]
    assert np.abs(np.array(corners)[:, 2]).max() < 1e-6
    markers = [_clip(viz, f"point_{i}").tracks["position"].values for i in range(4)]
    at_rest = np.array([values[-1] for values in markers])
    # Each corner carries one marker, and each marker is on a corner.
    distance = np.linalg.norm(at_rest[:, None] - np.array(corners)[None], axis=2)
    assert np.allclose(np.sort(distance.min(axis=1)), 0.0, atol=1e-12)
    assert sorted(distance.argmin(axis=1)) == [0, 1, 2, 3]
    # The scene's node is a small ball (a point contact), drawn still at the final pose.
    for i in range(4):
        node = _node(viz, f"point_{i}")
        assert _object(node)["geometry"]["type"] == "SphereGeometry"
        assert 0 < _object(node)["geometry"]["radius"] < 0.02  # a marker: smaller than the box
        assert np.allclose(_matrix(node)[:3, 3], at_rest[i], atol=1e-12)


def test_contact_markers_follow_their_frames_through_the_animation(played):
    scene, result, viz, _ = played("box_on_floor")
    tracks = [_clip(viz, f"point_{i}").tracks["position"] for i in range(len(scene.contacts))]
    assert len(tracks[0].values) == viz.timeline.times.size > 10
    for k, q in enumerate(viz.timeline.q):
        expected = _world_points(scene, q)
        for i, track in enumerate(tracks):
            assert np.allclose(track.values[k], expected[i], atol=1e-12), (k, i)
    # It falls 0.15 m: the markers move with it, from the start (0.2 - 0.05 above the floor).
    heights = np.array(tracks[0].values)[:, 2]
    assert heights[0] == pytest.approx(0.15, abs=1e-9) and abs(heights[-1]) < 1e-6


def test_a_contact_sphere_is_drawn_with_its_radius():
    play = _play()
    scene = pinsettle.load_scene(ROBOTS / "box_on_floor.toml")
    scene.add_contact("body", (0.05, 0.0, 0.0), radius=0.03, name="ball")
    viz = play.play(scene, live=False)
    geometry = _object(_node(viz, "point_4"))["geometry"]
    assert geometry["type"] == "SphereGeometry" and geometry["radius"] == 0.03
    centre = _world_points(scene, viz.result.q)[4]
    assert np.allclose(_clip(viz, "point_4").tracks["position"].values[-1], centre, atol=1e-12)
    # Not touching (the box's half height 0.05 > 0.03): no force drawn at it.
    assert "ball" not in [c.name for c in viz.result.contacts]
    assert "normal_4" not in _children(viz)


# --- the ground ---------------------------------------------------------------------------------


@pytest.mark.parametrize("name", ["box_on_floor", "box_on_incline"])
def test_the_ground_is_a_thin_slab_in_its_plane_under_the_robot(name, played):
    scene, result, viz, _ = played(name)
    (ground,) = scene.grounds
    normal, point = np.asarray(ground.normal), np.asarray(ground.point)
    node = _node(viz, "ground_0")
    box = _object(node)["geometry"]
    assert box["type"] == "BoxGeometry"
    matrix = _matrix(node)
    rotation, centre = matrix[:3, :3], matrix[:3, 3]
    assert np.allclose(rotation.T @ rotation, np.eye(3), atol=1e-12)  # turned, not stretched
    # Its thickness (the box's z, "depth") along the ground's normal; its top face in the plane.
    assert np.allclose(rotation[:, 2], normal, atol=1e-12)
    top = centre + 0.5 * box["depth"] * normal
    assert float(normal @ (top - point)) == pytest.approx(0.0, abs=1e-12)
    # Under the mechanism at rest: the top face's centre is the projection of the centre of mass.
    com = pinocchio.centerOfMass(scene.model, scene.model.createData(), result.q)
    assert np.allclose(top, com - float(normal @ (com - point)) * normal, atol=1e-12)
    # Sized by the robot's extent: wider than the box's largest side several times, but not a
    # huge plane; thin.
    assert box["width"] == box["height"]
    assert 2 * 0.2 < box["width"] < 20 * 0.2 and box["depth"] < 0.02 * box["width"]
    material = _object(node)["material"]
    assert material["transparent"] and 0 < material["opacity"] < 1
    assert material["color"] == _contacts_module().GROUND_COLOR


def _on_a_turned_block(theta: float) -> Any:
    """free_body.urdf (0.2 x 0.1 x 0.1 m, 1 kg) on its four lower corners, 2 cm above the top
    face of a 2 x 1 x 0.2 m block turned by theta (rad) about y, and a floor plane below."""
    scene = pinsettle.load_scene(ROBOTS / "free_fall.toml")
    scene.add_ground((0.0, 0.0, -1.0), name="floor")
    scene.add_ground(box=(2.0, 1.0, 0.2), rpy=(0.0, -theta, 0.0), friction=0.5, name="block")
    for x in (-0.1, 0.1):
        for y in (-0.05, 0.05):
            scene.add_contact("body", (x, y, -0.05))
    up = 0.17 * np.array([-np.sin(theta), 0.0, np.cos(theta)])
    scene.set_start(root_joint=[*up, np.cos(-theta / 2), 0.0, np.sin(-theta / 2), 0.0])
    return scene


@pytest.fixture(scope="module")
def on_a_block():
    scene = _on_a_turned_block(np.arctan(0.2))
    return scene, _play().play(scene, live=False)


def test_a_box_ground_is_drawn_as_its_own_box(on_a_block):
    scene, viz = on_a_block
    floor, block = scene.grounds
    node = _node(viz, "ground_1")
    box = _object(node)["geometry"]
    # Its own size along its own axes (meshcat's width, height, depth: x, y, z), at its centre,
    # turned as the ground is (its top face's normal the ground's).
    assert box["type"] == "BoxGeometry"
    assert (box["width"], box["height"], box["depth"]) == pytest.approx(block.box, abs=1e-12)
    matrix = _matrix(node)
    assert np.allclose(matrix[:3, 3], block.point, atol=1e-12)
    assert np.allclose(matrix[:3, :3], block.rotation(), atol=1e-12)
    assert np.allclose(matrix[:3, 2], block.normal, atol=1e-12)
    assert _object(node)["material"] == _object(_node(viz, "ground_0"))["material"]
    # The plane beside it is still a slab, its top face in the plane.
    slab = _object(_node(viz, "ground_0"))["geometry"]
    assert slab["width"] == slab["height"] and slab["depth"] < 0.02 * slab["width"]
    top = _matrix(_node(viz, "ground_0"))[:3, 3] + 0.5 * slab["depth"] * np.asarray(floor.normal)
    assert top[2] == pytest.approx(floor.point[2], abs=1e-12)


def test_the_normal_arrows_on_a_box_ground_are_along_its_face(on_a_block):
    scene, viz = on_a_block
    result, block = viz.result, scene.grounds[1]
    assert result.converged and len(result.contacts) == 4
    assert all(c.ground == "block" for c in result.contacts)
    for name, matrix in _arrows(viz, scene, "normal").items():
        (contact,) = [c for c in result.contacts if c.name == name]
        # Along the contact's own normal: the block's top face, not the floor's +z.
        direction = matrix[:3, 1] / np.linalg.norm(matrix[:3, 1])
        assert np.allclose(direction, contact.normal, atol=1e-9)
        assert np.allclose(direction, block.normal, atol=1e-9)
        assert np.allclose(matrix[:3, 3], contact.point, atol=1e-12)
    assert abs(block.normal[2]) < 0.99  # turned: the check above tells it from +z


def test_the_legend_names_box_grounds_apart_from_planes(on_a_block):
    _, viz = on_a_block
    texts = [mark["text"] for mark in viz._overlay()["legend"]]
    assert "slab: ground floor (friction 0.5)" in texts
    assert "box: ground block (friction 0.5)" in texts
    # A scene of box grounds only has no slab entry.
    scene = _on_a_turned_block(0.1)
    scene.grounds.pop(0)
    legend = _contacts_module().contacts_legend(scene, viz.result)
    assert [m["text"] for m in legend if "ground" in m["text"]] == [
        "box: ground block (friction 0.5)"
    ]


# --- the forces at the end ----------------------------------------------------------------------


def _arrows(viz: Any, scene: Any, kind: str) -> dict[str, np.ndarray]:
    """Contact name -> the placement of its ``kind`` arrow (drawn along +y, unit length scaled)."""
    names = [c.name for c in scene.contacts]
    children = _children(viz)
    return {
        names[int(child.split("_")[1])]: _matrix(_node(viz, child))
        for child in children
        if child.startswith(kind + "_")
    }


def test_the_force_arrows_are_the_results_contact_forces(played):
    scene, result, viz, _ = played("box_on_incline")
    assert result.converged and len(result.contacts) == 4
    normals, tangentials = _arrows(viz, scene, "normal"), _arrows(viz, scene, "tangential")
    assert sorted(normals) == sorted(tangentials) == sorted(c.name for c in result.contacts)
    (ground,) = scene.grounds
    ratios, total = [], np.zeros(3)
    for contact in result.contacts:
        for matrix, force in (
            (normals[contact.name], contact.normal_force * contact.normal),
            (tangentials[contact.name], contact.tangential_force),
        ):
            vector = matrix[:3, 1]  # the arrow's +y, scaled to its length
            assert np.allclose(matrix[:3, 3], contact.point, atol=1e-12)  # where it touches
            assert np.allclose(
                vector / np.linalg.norm(vector), force / np.linalg.norm(force), atol=1e-9
            )
            ratios.append(np.linalg.norm(vector) / np.linalg.norm(force))
            total += vector
        # The normal arrow along the slope's normal (from the scene file).
        assert np.allclose(
            normals[contact.name][:3, 1] / np.linalg.norm(normals[contact.name][:3, 1]),
            ground.normal,
            atol=1e-12,
        )
    # One scale for every arrow (metres per newton), the largest force the longest arrow.
    assert np.allclose(ratios, ratios[0], rtol=1e-9)
    # The arrows, read back to newtons, carry the box's weight (Pinocchio's mass and gravity).
    mass = pinocchio.computeTotalMass(scene.model)
    weight = mass * scene.model.gravity.linear
    assert np.allclose(total / ratios[0], -weight, atol=1e-6)


def test_the_force_arrows_show_at_the_end_only(played):
    play = _play()
    scene, result, viz, _ = played("box_on_floor")
    end = viz.timeline.duration * play.FPS
    for i in range(4):
        visible = _clip(viz, f"normal_{i}").tracks["visible"]
        assert visible.values == [False, False, True]
        assert visible.frames[-1] == pytest.approx(end)
    # On a level floor the tangential forces are round-off (below 1e-15 N): no arrow for them.
    assert max(np.linalg.norm(c.tangential_force) for c in result.contacts) < 1e-12
    assert not [child for child in _children(viz) if child.startswith("tangential")]


def test_sticking_and_sliding_contacts_have_their_own_colour(played):
    play, contacts = _play(), _contacts_module()
    scene, result, _, _ = played("box_on_incline")
    assert all(c.sticking for c in result.contacts)
    first, *rest = result.contacts
    sliding = dataclasses.replace(
        result, contacts=(dataclasses.replace(first, sticking=False), *rest)
    )
    viz = play.play(scene, sliding, live=False)
    index = {c.name: i for i, c in enumerate(scene.contacts)}
    for contact in sliding.contacts:
        colour = contacts.STICKING_COLOR if contact.sticking else contacts.SLIDING_COLOR
        for kind in ("normal", "tangential"):
            for part in ("shaft", "head_0"):
                node = _node(viz, f"{kind}_{index[contact.name]}")[part]
                assert _object(node)["material"]["color"] == colour, (contact.name, kind)
    assert contacts.STICKING_COLOR != contacts.SLIDING_COLOR
    texts = [mark["text"] for mark in viz._overlay()["legend"]]
    assert any("sticking (3," in t for t in texts) and any(
        "sliding" in t and "(1," in t for t in texts
    )


def test_the_legend_names_the_ground_and_the_contacts(played):
    scene, result, viz, html = played("box_on_floor")
    legend = viz._overlay()["legend"]
    colours = {mark["color"] for mark in legend}
    contacts = _contacts_module()
    for colour in (contacts.GROUND_COLOR, contacts.CONTACT_COLOR, contacts.STICKING_COLOR):
        assert f"#{colour:06x}" in colours
    texts = " | ".join(mark["text"] for mark in legend)
    total = sum(c.normal_force for c in result.contacts)
    assert "ground1 (friction 0.5)" in texts and f"normal sum {total:.4g} N" in texts
    assert "sliding" not in texts
    assert "contact points" in html.read_text("utf-8")


def test_the_camera_frames_the_arrows_tips(played):
    animation = importlib.import_module("pinsettle._play_animation")
    forces = importlib.import_module("pinsettle._play_forces")
    scene, result, viz, _ = played("box_on_floor")
    # For a view 1 m across: the largest force's arrow ARROW_LENGTH long (the loads' rule), the
    # others in proportion, from each contact point along its force (no tangential force).
    tips = animation._mark_tips(scene, result, 1.0)
    largest = max(c.normal_force for c in result.contacts)
    expected = [
        c.point + forces.ARROW_LENGTH * c.normal_force / largest * np.asarray(c.normal)
        for c in result.contacts
    ]
    assert np.allclose(tips, expected, atol=1e-12)


# --- a scene without grounds --------------------------------------------------------------------


def test_a_scene_without_grounds_draws_and_imports_none_of_it():
    # In a fresh process: a fixed pendulum and a free body falling (floating, no ground) played;
    # no node, command, clip or legend entry of contacts, and their module never imported.
    code = (
        "import sys, umsgpack, pinsettle\n"
        "from pinsettle import play\n"
        "for name in ('pendulum', 'free_fall'):\n"
        "    viz = play.play(name, live=False)\n"
        "    nodes = 'contacts' in viz.window.tree['meshcat']['pinsettle']\n"
        "    paths = [umsgpack.unpackb(c).get('path', '') for c in viz.window.commands()]\n"
        "    sent = any('/contacts' in p for p in paths)\n"
        "    clips = any('/contacts' in p.lower() for p in viz.animation.clips)\n"
        "    legend = ' '.join(m['text'] for m in viz._overlay()['legend'])\n"
        "    print(name, len(paths) > 0, nodes, sent, clips, 'slab' in legend)\n"
        "print('imported', 'pinsettle._play_contacts' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.splitlines() == [
        "pendulum True False False False False",
        "free_fall True False False False False",
        "imported False",
    ]


def test_a_scene_with_grounds_sends_them(played):
    import umsgpack

    _, _, viz, _ = played("box_on_floor")
    paths = [umsgpack.unpackb(c).get("path", "") for c in viz.window.commands()]
    assert "/meshcat/pinsettle/contacts/ground_0" in paths
    assert "pinsettle._play_contacts" in sys.modules


def test_a_result_of_another_scene_is_a_clear_error(played):
    play = _play()
    _, result, _, _ = played("box_on_floor")
    scene = pinsettle.load_scene(ROBOTS / "box_on_floor.toml")
    scene.contacts.clear()
    scene.add_contact("body", (0.0, 0.0, -0.05), name="middle")
    with pytest.raises(ValueError, match=r"result.contacts names contacts the scene does not have"):
        play.play(scene, result, live=False)


# --- on screen ----------------------------------------------------------------------------------


def test_screenshot_shows_the_contacts_and_their_forces_at_the_end(played, browser, tmp_path):  # noqa: F811
    contacts = _contacts_module()
    scene, result, viz, html = played("box_on_floor")
    end = screenshot(browser, html.as_uri() + "#end", tmp_path / "end.png")
    moving = screenshot(
        browser, f"{html.as_uri()}#t={0.2 * viz.timeline.speed:.6g}", tmp_path / "m.png"
    )
    assert _color_pixels(end, contacts.STICKING_COLOR) > 200
    assert _color_pixels(moving, contacts.STICKING_COLOR) == 0  # forces of the rest only
    assert (
        _color_pixels(end, contacts.CONTACT_COLOR) > 20
        and _color_pixels(moving, contacts.CONTACT_COLOR) > 20
    )
