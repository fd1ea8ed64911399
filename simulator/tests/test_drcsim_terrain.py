"""Terrain that matters: loose rubble, soft mud, slopes; configurations 1..5 get harder."""

from __future__ import annotations

import itertools

import pytest
from drcsim.worlds import CONFIG_NAMES, load_world


def test_walking_configurations_get_harder_from_1_to_5() -> None:
    specs = [load_world("vrc_task_2", config) for config in CONFIG_NAMES]
    mud = [s.terrain["mud"] for s in specs]
    rubble = [s.terrain["rubble"] for s in specs]
    hill = [s.terrain["hill"] for s in specs]

    def rising(values: list[float]) -> bool:
        return all(a < b for a, b in itertools.pairwise(values))

    assert rising([-m["friction"] for m in mud]) and rising([-m["stiffness"] for m in mud])
    assert rising([r["blocks"] for r in rubble]) and rising([r["max_height"] for r in rubble])
    assert rising([h["slope"] for h in hill]) and rising([h["rise"] for h in hill])
    assert rising([-s.ground_friction for s in specs[1:]])


def test_rubble_is_loose_and_moves_when_pushed(make_sim) -> None:
    sim = make_sim("vrc_task_2", "5")
    client, blocks = sim.client, sim.scene.rubble
    assert len(blocks) >= 30 and all(client.getDynamicsInfo(b, -1)[0] > 0 for b in blocks)
    sizes = {round(client.getCollisionShapeData(b, -1)[0][3][2], 3) for b in blocks}
    assert len(sizes) > 10  # of varied size
    before = client.getBasePositionAndOrientation(blocks[0])[0]
    sim.step(200)
    assert client.getBasePositionAndOrientation(blocks[0])[0] == pytest.approx(
        before, abs=3e-3
    )  # settled
    mass = client.getDynamicsInfo(blocks[0], -1)[0]
    for _ in range(100):  # a shove of twice its weight for 0.1 s
        where = client.getBasePositionAndOrientation(blocks[0])[0]
        client.applyExternalForce(blocks[0], -1, [20.0 * mass, 0, 0], where, client.WORLD_FRAME)
        sim.step(1)
    assert abs(client.getBasePositionAndOrientation(blocks[0])[0][0] - before[0]) > 0.01


def test_the_hill_surface_is_where_the_terrain_says(make_sim) -> None:
    sim = make_sim("vrc_task_2", "4")
    hill = sim.spec.terrain["hill"]
    for x in (16.5, 17.0, 17.5, 18.4):
        expected = sim.scene.ground_height(x, 0.3)
        hit = sim.client.rayTest([x, 0.3, 2.0], [x, 0.3, -1.0])[0]
        assert hit[3][2] == pytest.approx(expected, abs=0.01)
    assert sim.scene.ground_height(17.5, 0.0) == pytest.approx(hill["rise"])
