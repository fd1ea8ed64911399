"""Terrain that matters: loose rubble, mud, slopes; configurations 1..5 get harder."""

from __future__ import annotations

import itertools

import pytest
from drcsim.local import LocalClient
from drcsim.mud import MudDrag
from drcsim.scene import MUD_BOTTOM
from drcsim.worlds import CONFIG_NAMES, load_world, shipped_document


def test_walking_configurations_get_harder_from_1_to_5() -> None:
    specs = [load_world("vrc_task_2", config) for config in CONFIG_NAMES]
    mud = [s.terrain["mud"] for s in specs]
    rubble = [s.terrain["rubble"] for s in specs]
    hill = [s.terrain["hill"] for s in specs]

    def rising(values: list[float]) -> bool:
        return all(a < b for a, b in itertools.pairwise(values))

    assert rising([-m["friction"] for m in mud]) and rising([m["depth"] for m in mud])
    assert rising([m["damping"] for m in mud])
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


def test_feet_sink_through_the_mud_and_stand_on_its_firm_bottom(make_sim) -> None:
    sim = make_sim("vrc_task_2", "5")
    client, robot, pit = sim.client, sim.scene.robot, sim.scene.mud[0]
    pos, orn = client.getBasePositionAndOrientation(robot)
    client.resetBasePositionAndOrientation(robot, [7.0, 0.0, pos[2] + 0.05], orn)
    LocalClient(sim).behaviour("stand")
    sim.step(800)
    for side in ("l_foot", "r_foot"):
        lower, upper = client.getAABB(robot, sim.scene.robot_links[side])
        assert lower[2] == pytest.approx(MUD_BOTTOM, abs=2e-3)  # on the bottom, not the surface
        assert upper[2] < pit.surface
    dragged = dict(sim.mud.dragged)  # feet and shins are in the mud, nothing else
    assert sim.scene.robot_links["l_foot"] in dragged and len(dragged) <= 6
    assert sum(dragged.values()) == pytest.approx(2 * pit.damping, rel=0.15)  # both legs


def test_a_robot_in_deep_mud_stands_on_its_bottom_as_documented(make_sim) -> None:
    # Only what the README promises: a world document (`--world-file`) with 30 cm of mud under
    # the start, and the command API. Links pass through the mud's surface: the robot stands
    # on the bottom, as tall as on the paved lot, not on the mud.
    document = shipped_document("vrc_task_2")
    mud = next(patch for patch in document["terrain"] if patch["kind"] == "mud")
    mud.update({"min": [-2.0, -2.0], "max": [2.0, 2.0], "depth": 0.3})
    heights = []
    for world in (document, None):
        api = LocalClient(make_sim("vrc_task_2", "1", world_document=world))
        api.behaviour("stand")
        state = api.step(1000)
        assert state["score"]["falls"] == 0
        heights.append(state["pelvis"]["position"][2])
    assert heights[0] == pytest.approx(heights[1], abs=0.01)


def _slide(sim, x: float) -> float:
    """Return how far a 2.4 kg box (a foot) slides from x at 1 m/s, mud-dragged as a link."""
    client = sim.client
    shape = client.createCollisionShape(client.GEOM_BOX, halfExtents=[0.13, 0.065, 0.025])
    box = client.createMultiBody(2.4, shape, -1, [x, 0.0, 0.03])
    drag = MudDrag(client, box, sim.scene.mud, 0.001)
    for step in range(100):
        drag.apply(step)
        client.stepSimulation()
    client.resetBaseVelocity(box, [1.0, 0.0, 0.0])
    start = client.getBasePositionAndOrientation(box)[0][0]
    speeds = []
    for step in range(100, 400):
        drag.apply(step)
        client.stepSimulation()
        speeds.append(client.getBaseVelocity(box)[0][0])
    # Only ever slowed (to within the contact solver's jitter at rest).
    assert all(-1e-4 <= b <= a + 1e-4 for a, b in itertools.pairwise(speeds))
    assert (drag.dragged != []) == (x > 5.0)  # no drag outside the pit
    return client.getBasePositionAndOrientation(box)[0][0] - start


def test_the_mud_drags_at_what_moves_in_it_and_nothing_outside(make_sim) -> None:
    sim = make_sim("vrc_task_2", "1")
    paved, mud = _slide(sim, 2.0), _slide(sim, 7.0)  # both on friction 1.0
    assert 0.0 < mud < 0.8 * paved
