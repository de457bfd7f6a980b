"""The stack's one oriented rectangle (services/bus/schemas/rectangle.py): its ray entry, distance,
containment and growth against brute force on seeded random rectangles, and every box of the stack
(vision footprints on the bus, obstacles on the bus, navigation's boxes, the supervisor's map and
memory, the sole of services.model.ground) using it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from services.bus.schemas.navigation import ObstacleMsg
from services.bus.schemas.perception import FootprintMsg
from services.bus.schemas.rectangle import Rectangle


def _random_rectangles(n: int, seed: int = 7) -> list[Rectangle]:
    rng = np.random.default_rng(seed)
    return [
        Rectangle(tuple(rng.uniform(-2, 2, 2)), tuple(rng.uniform(0.05, 1.5, 2)), float(rng.uniform(-4, 4)))
        for _ in range(n)
    ]


def test_ray_entry_distance_containment_and_growth_against_sampling():
    rng = np.random.default_rng(11)
    for rect in _random_rectangles(40):
        for _ in range(10):
            origin = rng.uniform(-3, 3, 2)
            angle = rng.uniform(-math.pi, math.pi)
            u = np.array([math.cos(angle), math.sin(angle)])
            # the ray's first point inside, by marching in 0.2 mm steps
            t = np.arange(0.0, 8.0, 2e-4)
            inside = np.all(np.abs(rect.to_local(origin + t[:, None] * u)) <= rect.half_m, axis=1)
            entry = rect.ray_entry(origin, u)
            if inside.any():
                assert entry == pytest.approx(t[np.argmax(inside)], abs=4e-4)
            else:
                assert entry == math.inf
            d = rect.distance(origin)
            assert d == pytest.approx(max(0.0, float(rect.signed_distance(origin)[0])))
            nearest = rect.nearest_point(origin)
            assert np.linalg.norm(origin - nearest) == pytest.approx(d, abs=1e-9)
            assert rect.grown(1e-9).contains(nearest)
            assert (d == 0.0) == rect.contains(origin)
            margin = float(rng.uniform(0.0, 0.3))
            local = np.abs(rect.to_local(origin)[0])
            assert rect.grown(margin).contains(origin) == bool(np.all(local <= rect.half_m + margin))
            assert rect.grown(-margin).contains(origin) == bool(np.all(local <= rect.half_m - margin))


def test_every_box_of_the_stack_is_this_rectangle():
    from services.collision import BoxObstacle
    from services.model import ground
    from supervisor.scene_map import BoxEstimate, distance_to_box, ray_entry

    assert ground.Rectangle is Rectangle
    fp = FootprintMsg(center=[1.0, 2.0], size=[0.8, 0.4], yaw=0.3, top_z=0.7, n_points=40)
    assert fp.rectangle == Rectangle((1.0, 2.0), (0.8, 0.4), 0.3)
    box = ObstacleMsg(name="table", center=[1.0, 2.0, 0.35], size=[0.8, 0.4, 0.7], yaw=0.3)
    assert box.footprint == fp.rectangle
    cylinder = ObstacleMsg(name="bin", kind="cylinder", center=[0.0, 1.0, 0.2], radius=0.2, height=0.4)
    assert cylinder.footprint == Rectangle((0.0, 1.0), (0.4, 0.4), 0.0)
    assert BoxObstacle("table", (1.0, 2.0, 0.35), (0.8, 0.4, 0.7), 0.3).footprint == fp.rectangle
    estimate = BoxEstimate("table", (1.0, 2.0, 0.35), (0.8, 0.4, 0.7), 0.3)
    assert estimate.footprint == fp.rectangle
    assert estimate.to_msg().footprint == fp.rectangle
    assert distance_to_box(estimate, 3.0, 2.0) == fp.rectangle.distance((3.0, 2.0))
    u = np.array([0.6, 0.8])
    assert ray_entry(estimate, np.zeros(2), u) == fp.rectangle.ray_entry((0.0, 0.0), u)
