"""The vehicle responds only to its interfaces, and only the seated robot's limbs move them."""

from __future__ import annotations

from drcsim.protocol import check_command


def _command(sim, **message) -> dict:
    return sim.apply_command(check_command(message))


def test_driving_through_the_interfaces(make_sim, place) -> None:
    sim = make_sim("vrc_task_1", "1")
    refused = _command(sim, op="behaviour", name="drive", direction="forward", throttle=1.0)
    assert refused["ok"] is False and "seat" in refused["error"]
    assert _command(sim, op="behaviour", name="enter_vehicle")["ok"] is False  # too far
    door = sim.scene.course["vehicle"]["driver_door"]
    place(sim, door[0], door[1], 0.0)  # as a walk to the door ends (the walk is tested elsewhere)
    assert _command(sim, op="behaviour", name="enter_vehicle")["ok"]
    car = sim.scene.vehicle
    start_x = sim.client.getBasePositionAndOrientation(car)[0][0]

    _command(sim, op="behaviour", name="drive", direction="neutral", throttle=1.0)
    sim.step(1000)
    assert abs(sim.client.getBasePositionAndOrientation(car)[0][0] - start_x) < 0.05
    assert sim.drive.interface_positions()["throttle_pedal"] > 0.3  # pedal down, no gear

    _command(sim, op="behaviour", name="drive", direction="forward", throttle=1.0)
    sim.step(1500)
    moved_x = sim.client.getBasePositionAndOrientation(car)[0][0]
    assert moved_x > start_x + 1.0 and sim.drive.speed() > 1.0
    # The hands hold the controls (grasp joints) and the arms are the drive behaviour's.
    assert sim.behaviours.grasps.held["left"][1] == "steering_wheel"
    refused = _command(sim, op="joints", position={"r_arm_elx": -0.5})
    assert refused["ok"] is False and "drive (right hand)" in refused["error"]
    _command(sim, op="behaviour", name="drive", direction="forward", steering_wheel=0.6)
    sim.step(1500)
    positions = sim.drive.interface_positions()
    assert abs(positions["steering_wheel"] - 0.6) < 0.1
    assert positions["throttle_pedal"] < 0.02  # the foot came off: the spring returned it

    _command(
        sim,
        op="behaviour",
        name="drive",
        direction="forward",
        throttle=0.0,
        brake=1.0,
        hand_brake=True,
    )
    sim.step(3500)  # the right hand sets the switch, then takes the hand brake
    assert sim.drive.speed() < 0.05
    positions = sim.drive.interface_positions()
    assert positions["brake_pedal"] > 0.3 and positions["hand_brake"] > 0.3
    assert _command(sim, op="behaviour", name="exit_vehicle")["ok"]
    assert not sim.behaviours.seat.seated and not sim.scorer.down
    assert sim.behaviours.grasps.held == {}
