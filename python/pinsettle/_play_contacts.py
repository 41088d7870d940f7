"""Ground contacts drawn in the playback: each ground plane as a thin translucent slab under the
mechanism, each box ground as its own box, each contact point (a small ball) or sphere (of its
radius) following its body, and at the end the force the ground exerts at each closed contact,
normal and tangential, as arrows coloured by whether the contact sticks or slides; and their
entries of the legend.

Imported only for a scene with grounds: a scene without them runs none of this.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np
import pinocchio

from ._play_forces import _frame_points, _hex, _load_arrow, _Sizes, arrow_matrix
from ._play_timeline import FPS, Timeline
from ._scene import Scene
from ._scene_values import Ground
from ._solve import Contact, Result

#: The colours: grounds (lit, translucent), contact points, and the force arrows of a sticking
#: contact and of one sliding (its tangential force at the friction cone's edge).
GROUND_COLOR = 0x868E96
CONTACT_COLOR = 0xFAB005
STICKING_COLOR = 0x0B7285
SLIDING_COLOR = 0xC2255C
#: A ground's slab: its side and its thickness as shares of the view's size (wide enough to
#: be seen as a floor, not so wide that it swamps the view).
GROUND_SIDE = 3.0
GROUND_THICKNESS = 0.01
#: A tangential force below this share of the largest contact force is not drawn (its arrow
#: would be a speck).
_TANGENTIAL_SHOWN = 1e-3
_Z = np.array([0.0, 0.0, 1.0])  # meshcat's boxes are centred, their thickness along z here


def ground_matrix(
    point: np.ndarray, normal: np.ndarray, center: np.ndarray, size: float
) -> np.ndarray:
    """The placement of a ground's slab (a box of ``GROUND_SIDE * size`` by the same by
    ``GROUND_THICKNESS * size``, its thickness along its local z): its top face in the plane
    through ``point`` with unit ``normal``, centred under ``center`` (projected on the plane)."""
    normal = np.asarray(normal, dtype=float)
    under = center - float(normal @ (center - point)) * normal
    m = np.eye(4)
    m[:3, :3] = pinocchio.Quaternion.FromTwoVectors(_Z, normal).matrix()
    m[:3, 3] = under - 0.5 * GROUND_THICKNESS * size * normal
    return m


def box_matrix(ground: Ground) -> np.ndarray:
    """The placement of a box ground's box (meshcat's boxes are centred): at its centre, turned
    by its rotation."""
    m = np.eye(4)
    m[:3, :3] = ground.rotation()
    m[:3, 3] = ground.point
    return m


def draw_grounds(viz: Any, scene: Scene, size: float, center: np.ndarray) -> None:
    """Each ground, translucent and still: a plane as a thin slab under ``center`` (the final
    centre of mass) sized by the view's ``size`` (m), a box ground as its own box."""
    import meshcat.geometry as mg

    side, thickness = GROUND_SIDE * size, GROUND_THICKNESS * size
    material = mg.MeshLambertMaterial(color=GROUND_COLOR, opacity=0.45, transparent=True)
    for i, ground in enumerate(scene.grounds):
        node = viz.viewer[f"contacts/ground_{i}"]
        if ground.box is not None:
            node.set_object(mg.Box(list(ground.box)), material)
            node.set_transform(box_matrix(ground))
            continue
        node.set_object(mg.Box([side, side, thickness]), material)
        point, normal = np.asarray(ground.point), np.asarray(ground.normal)
        node.set_transform(ground_matrix(point, normal, center, size))


def draw_contact_points(
    viz: Any, scene: Scene, timeline: Timeline, sizes: _Sizes, tracks: Any
) -> None:
    """Each contact: a sphere of its radius (a small ball for a point) at its centre,
    following its body."""
    import meshcat.geometry as mg

    if not scene.contacts:
        return
    ends = [(c.frame, c.point) for c in scene.contacts]
    at = _frame_points(viz.model, timeline.q, ends)  # (keys, contacts, 3)
    material = mg.MeshBasicMaterial(color=CONTACT_COLOR)
    for i, contact in enumerate(scene.contacts):
        node = viz.viewer[f"contacts/point_{i}"]
        node.set_object(mg.Sphere(contact.radius if contact.radius > 0 else sizes.ball), material)
        matrices = np.tile(np.eye(4), (len(at), 1, 1))
        matrices[:, :3, 3] = at[:, i]
        node.set_transform(matrices[-1])
        tracks.poses(node.path, matrices)


def contact_arrows(scene: Scene, result: Result) -> list[tuple[str, int, Contact, np.ndarray]]:
    """The arrows of the contact forces at the end: for each closed contact of ``result``,
    ("normal" or "tangential", its index in ``scene.contacts``, the contact, the force on the
    body, N, world); a tangential force too small to be seen is left out.

    Raises:
        ValueError: ``result`` names a contact that ``scene`` does not have (a result of
            another scene).
    """
    index = {c.name: i for i, c in enumerate(scene.contacts)}
    unknown = [c.name for c in result.contacts if c.name not in index]
    if unknown:
        raise ValueError(
            f"result.contacts names contacts the scene does not have: {unknown} (the scene's: "
            f"{list(index)}); pass the result of a solve of this scene"
        )
    forces = [(c, c.normal_force * np.asarray(c.normal)) for c in result.contacts]
    forces += [(c, np.asarray(c.tangential_force, dtype=float)) for c in result.contacts]
    largest = max((float(np.linalg.norm(f)) for _, f in forces), default=0.0)
    out = []
    for k, (contact, force) in enumerate(forces):
        kind = "normal" if k < len(result.contacts) else "tangential"
        norm = float(np.linalg.norm(force))
        if norm > 0 and (kind == "normal" or norm > _TANGENTIAL_SHOWN * largest):
            out.append((kind, index[contact.name], contact, force))
    return out


def _scale(arrows: list[tuple[str, int, Contact, np.ndarray]], sizes: _Sizes) -> float:
    """Metres of arrow per newton: the largest contact force ``sizes.arrow`` long (as the
    largest load's), the others in proportion."""
    largest = max((float(np.linalg.norm(a[3])) for a in arrows), default=1.0)
    return sizes.arrow / largest


def draw_contact_forces(
    viz: Any, scene: Scene, result: Result, timeline: Timeline, sizes: _Sizes, tracks: Any
) -> None:
    """Each closed contact's force at the end: an arrow from where it touches along its
    normal force and one along its tangential force, in ``STICKING_COLOR`` or
    ``SLIDING_COLOR``, shown once the motion is over."""
    end = timeline.duration * FPS
    arrows = contact_arrows(scene, result)
    scale = _scale(arrows, sizes)
    for kind, i, contact, force in arrows:
        node = viz.viewer[f"contacts/{kind}_{i}"]
        _load_arrow(node, STICKING_COLOR if contact.sticking else SLIDING_COLOR, sizes)
        node.set_transform(arrow_matrix(np.asarray(contact.point), scale * force))
        if end > 0:  # hidden while it moves: the forces are those of the rest
            tracks.visibility(node.path, [0.0, end - 1e-6, end], np.array([False, False, True]))


def draw_contacts(
    viz: Any,
    scene: Scene,
    result: Result,
    timeline: Timeline,
    size: float,
    center: np.ndarray,
    tracks: Any,
) -> None:
    """The grounds, the contact points and the contact forces drawn, their dimensions from the
    view's ``size`` (m), the grounds under ``center``, their motion added to ``tracks``."""
    sizes = _Sizes.of(size)
    draw_grounds(viz, scene, size, center)
    draw_contact_points(viz, scene, timeline, sizes, tracks)
    draw_contact_forces(viz, scene, result, timeline, sizes, tracks)


def contact_tips(scene: Scene, result: Result, size: float) -> np.ndarray:
    """Where the contact force arrows end (world), drawn for a view of ``size`` (m): for the
    camera to frame them too."""
    arrows = contact_arrows(scene, result)
    scale = _scale(arrows, _Sizes.of(size))
    tips = [np.asarray(contact.point) + scale * force for _, _, contact, force in arrows]
    return np.reshape(tips, (-1, 3))


def _forces_text(result: Result, sticking: bool) -> str:
    closed = [c for c in result.contacts if c.sticking == sticking]
    if not closed:
        return ""
    total = sum(c.normal_force for c in closed)
    how = "sticking" if sticking else "sliding (at the friction cone's edge)"
    return (
        f"arrows at the end: contact forces, normal and tangential, {how} "
        f"({len(closed)}, normal sum {total:.4g} N)"
    )


def _grounds_text(grounds: Iterable[Ground]) -> str:
    return ", ".join(f"{g.name} (friction {g.friction:.3g})" for g in grounds)


def contacts_legend(scene: Scene, result: Result) -> list[dict[str, Any]]:
    """What the grounds, contact points and contact forces drawn are: ``{"color", "text",
    "nodes"}`` (for the overlay; see ``_play_animation.legend``)."""
    grounds = ["contacts/ground_*"]
    entries = [
        (GROUND_COLOR, f"{mark}: ground {names}", grounds)
        for mark, names in (
            ("slab", _grounds_text(g for g in scene.grounds if g.box is None)),
            ("box", _grounds_text(g for g in scene.grounds if g.box is not None)),
        )
        if names
    ]
    if scene.contacts:
        points = f"balls: contact points and spheres ({len(scene.contacts)})"
        entries.append((CONTACT_COLOR, points, ["contacts/point_*"]))
    arrows = ["contacts/normal_*", "contacts/tangential_*"]
    entries += [(STICKING_COLOR, _forces_text(result, True), arrows)]
    entries += [(SLIDING_COLOR, _forces_text(result, False), arrows)]
    return [
        {"color": _hex(color), "text": text, "nodes": nodes}
        for color, text, nodes in entries
        if text
    ]
