"""Models generated from code and worlds kept as data."""

from __future__ import annotations

import pytest
from drcsim.errors import WorldError
from drcsim.models.humanoid import ALL_JOINTS, BODY_JOINTS
from drcsim.worlds import CONFIG_NAMES, WORLD_NAMES, load_world

ATLAS_JOINTS = [
    "back_bkz",
    "back_bky",
    "back_bkx",
    "neck_ry",
    *[f"{s}_leg_{j}" for s in "lr" for j in ("hpz", "hpx", "hpy", "kny", "aky", "akx")],
    *[f"{s}_arm_{j}" for s in "lr" for j in ("shz", "shx", "ely", "elx", "wry", "wrx")],
]


def test_humanoid_has_atlas_joint_layout_with_limits(make_sim) -> None:
    assert [spec.name for spec in BODY_JOINTS] == ATLAS_JOINTS
    sim = make_sim("vrc_task_2")
    client, robot = sim.client, sim.scene.robot
    total_mass = sum(
        client.getDynamicsInfo(robot, link)[0] for link in range(-1, client.getNumJoints(robot))
    )
    assert 120 < total_mass < 180
    for spec in ALL_JOINTS:
        info = client.getJointInfo(robot, sim.scene.robot_joints[spec.name])
        assert (info[8], info[9], info[10], info[11]) == pytest.approx(
            (spec.lower, spec.upper, spec.effort, spec.velocity)
        )


def test_every_world_has_five_distinct_seeded_configurations() -> None:
    for world in WORLD_NAMES:
        specs = [load_world(world, config) for config in CONFIG_NAMES]
        assert len({spec.seed for spec in specs}) == 5
        assert all(len(spec.checkpoints) == 4 for spec in specs)
        layouts = {
            (spec.robot_start, repr(spec.objects), repr(spec.terrain), spec.ground_friction)
            for spec in specs
        }
        assert len(layouts) == 5


def test_unknown_world_or_configuration_is_an_error() -> None:
    with pytest.raises(WorldError):
        load_world("vrc_task_9", 1)
    with pytest.raises(WorldError):
        load_world("vrc_task_1", 6)


def test_worlds_contain_their_task_objects(make_sim) -> None:
    driving, manipulation = make_sim("vrc_task_1"), make_sim("vrc_task_3")
    assert driving.scene.vehicle is not None and len(driving.scene.gates) == 3
    joints = driving.scene.vehicle_joints
    assert {"steering_wheel", "throttle_pedal", "brake_pedal", "hand_brake", "fnr_switch"} <= set(
        joints
    )
    assert manipulation.scene.hose is not None and manipulation.scene.standpipe is not None
