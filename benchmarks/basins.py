"""Basin fidelity of the automatic step: does a release end in the basin the mechanism's own
motion leads to?

The bistable pendulum of robots/bistable_pendulum.toml (spring stiffness 30, 40, 55 N/m, rest
length 1.3, 1.5, 1.6 m, with and without a 0.5 N m load on the hinge) is released at rest from
30 angles in [-2.9, 2.9] rad. Each release is solved with a fine fixed step (2e-4 s, the
reference) and with the automatic step at several (dt_safety, backtrack) settings; a run that
ends more than 1e-4 rad from the reference's rest counted as a different basin. A coarse step
can carry the mechanism over a hump in one stride (the energy of semi-implicit Euler is only
kept to O(h^2)), and stopping dead one step past a peak lands it further on.

Run: python benchmarks/basins.py (about a minute).
"""

from __future__ import annotations

import argparse
import itertools
from collections.abc import Iterator, Sequence

import numpy as np
import pinsettle

SETTINGS = [(0.2, False), (0.3, False), (0.2, True), (0.3, True), (0.4, True), (0.5, True)]
TOLERANCE = 1e-4  # rad


def bistable(stiffness: float, rest_length: float, load: float | None) -> pinsettle.Scene:
    urdf = pinsettle.scene_path("bistable_pendulum").parent / "pendulum.urdf"
    scene = pinsettle.Scene.from_urdf(urdf).add_spring(
        {"frame": "arm", "point": [0.0, 0.0, -1.0]},
        {"frame": "universe", "point": [0.0, 0.0, -2.0]},
        stiffness=stiffness,
        rest_length=rest_length,
    )
    if load is not None:
        scene.add_load("hinge", load)
    return scene


def releases() -> Iterator[tuple[pinsettle.Scene, np.ndarray]]:
    """(scene, start) of every release."""
    for k, r0, load in itertools.product((30.0, 40.0, 55.0), (1.3, 1.5, 1.6), (None, 0.5)):
        scene = bistable(k, r0, load)
        for t0 in np.linspace(-2.9, 2.9, 30):
            yield scene, np.array([t0])


#: (dt_safety, backtrack), and the releases that ended elsewhere with them: (start angle, rest,
#: reference rest).
Setting = tuple[float | str, bool]
Missed = dict[Setting, list[tuple[float, float, float]]]


def measure(settings: Sequence[Setting] = SETTINGS) -> tuple[int, Missed]:
    """The number of releases and, per (dt_safety, backtrack), those that ended elsewhere than
    the reference (scene index, start angle, rest, reference rest)."""
    off: Missed = {s: [] for s in settings}
    count = 0
    for scene, q0 in releases():
        count += 1
        reference = pinsettle.solve(scene, q0, dt=2e-4, max_steps=10**6)
        assert reference.converged, q0
        for c, backtrack in settings:
            result = pinsettle.solve(scene, q0, dt_safety=c, backtrack=backtrack)
            if not (result.converged and abs(result.q[0] - reference.q[0]) <= TOLERANCE):
                rests = (float(q0[0]), float(result.q[0]), float(reference.q[0]))
                off[(c, backtrack)].append(rests)
    return count, off


def main() -> None:
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    count, off = measure()
    print("| dt_safety | backtrack | releases in another basin |")
    print("| ---: | --- | ---: |")
    for (c, backtrack), runs in off.items():
        print(f"| {c} | {'on' if backtrack else 'off'} | {len(runs)} of {count} |")


if __name__ == "__main__":
    main()
