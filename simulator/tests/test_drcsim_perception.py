"""The world is known only through sensors: a noisy state estimate and a rough briefing."""

from __future__ import annotations

import math

import numpy as np
from drcsim._bullet import pybullet
from drcsim.local import LocalClient
from drcsim.protocol import check_command, encode
from drcsim.sensors import LEFT_EYE_IN_HEAD, SensorSettings, whole_level_noise


def test_state_is_an_estimate_from_noisy_sensors_not_ground_truth(make_sim) -> None:
    sim = make_sim("vrc_task_2", "1")
    client = LocalClient(sim)
    client.behaviour("walk", pose=[4.0, 0.5, 0.0])
    state = client.step(6000)
    true_pos, _ = sim.client.getBasePositionAndOrientation(sim.scene.robot)
    error = math.dist(state["pelvis"]["position"][:2], true_pos[:2])
    assert 0.0 < error < 0.3  # dead reckoning drifts, a little
    joints = np.array(state["joints"]["position"])
    assert 0.0 < np.max(np.abs(joints - sim.controller.position)) < 0.01
    assert client.state() == client.state()  # reading the state changes nothing


def test_the_briefing_gives_rough_positions_and_the_task(make_sim) -> None:
    for world in ("vrc_task_1", "vrc_task_3"):
        sim = make_sim(world, "2")
        briefing = LocalClient(sim).hello()["course"]
        exact = sim.scene.course
        assert briefing["task"]["checkpoints"] == [c["name"] for c in sim.spec.checkpoints]
        items = [(briefing[k], exact[k], "pose") for k in ("vehicle", "table") if k in exact]
        items += [(briefing["gates"][g], exact["gates"][g], "pose") for g in exact.get("gates", {})]
        if "hose" in exact:
            items += [(briefing["hose"], exact["hose"], "coupler")]
            items += [(briefing["standpipe"], exact["standpipe"], "inlet")]
        errors = [math.dist(b[key][:2], e[key][:2]) for b, e, key in items]
        assert all(
            err <= b["accuracy_m"] + 0.01 for err, (b, _, _) in zip(errors, items, strict=True)
        )
        assert max(errors) > 0.01  # not the exact poses


def test_the_briefing_lays_out_the_terrain_sections(make_sim) -> None:
    briefing = LocalClient(make_sim("vrc_task_2", "4")).hello()["course"]
    assert briefing["terrain"]["rubble"] == {
        "kind": "rubble",
        "min": [11.0, -2.0],
        "max": [15.0, 2.0],
    }
    assert {p["kind"] for p in briefing["terrain"].values()} == {"mud", "rubble", "hill"}
    assert all(set(p) == {"kind", "min", "max"} for p in briefing["terrain"].values())


def test_the_stereo_pair_is_on_by_default(make_sim) -> None:
    assert SensorSettings().camera_stereo is True
    settings = SensorSettings(camera_width=32, camera_height=24)
    sim = make_sim("vrc_task_2", "1", sensors=settings)
    message = sim.sensors.compute("camera", 0.0)
    assert len(message["data"]) == len(message["right"]) == 32 * 24 * 3
    assert set(message["head_in_pelvis"]) == {"position", "orientation"}


def test_estimate_does_not_touch_the_physics(make_sim) -> None:
    first, second = make_sim("vrc_task_2", "3"), make_sim("vrc_task_2", "3")
    for sim in (first, second):
        sim.apply_command(check_command({"op": "behaviour", "name": "walk", "pose": [1, 0, 0]}))
    first.step(500)
    for _ in range(50):
        second.step(10)
        second.snapshot()
    assert first.state_vector() == second.state_vector()
    assert first.snapshot()["pelvis"] == second.snapshot()["pelvis"]


def test_sensors_are_computed_only_for_subscribed_topics(make_sim) -> None:
    published: list[str] = []
    sim = make_sim("vrc_task_2", "1", publish=lambda topic, _: published.append(topic))
    noise = sim.sensors.rngs  # each sensor draws its noise from its own generator
    fresh = {topic: rng.bit_generator.state for topic, rng in noise.items()}
    sim.step(200)
    assert {rng.bit_generator.state == fresh[t] for t, rng in noise.items()} == {True}
    assert set(published) == {"clock", "score"}
    sim.active_topics = {"imu"}
    sim.step(200)
    assert {t for t, rng in noise.items() if rng.bit_generator.state != fresh[t]} == {"imu"}
    assert published.count("imu") == 20 and set(published) == {"clock", "score", "imu"}


def _sensor_stream(sim) -> list[bytes]:
    topics = {"camera", "lidar", "imu", "joint_states", "contact"}
    messages: list[bytes] = []
    sim.options.publish = lambda topic, message: (
        messages.append(encode({topic: message})) if topic in topics else None
    )  # clock and score carry the wall time
    sim.active_topics = topics
    sim.apply_command(check_command({"op": "behaviour", "name": "walk", "pose": [1, 0, 0]}))
    sim.step(300)
    return messages


def test_sensor_messages_repeat_bit_for_bit(make_sim) -> None:
    settings = SensorSettings(camera_width=40, camera_height=30, camera_hz=50.0, lidar_beams=181)
    first = _sensor_stream(make_sim("vrc_task_2", "2", sensors=settings))
    second = _sensor_stream(make_sim("vrc_task_2", "2", sensors=settings))
    assert len(first) > 100 and first == second


def test_camera_noise_is_gaussian_rounded_to_whole_levels(make_sim) -> None:
    table = whole_level_noise(2.0)
    assert abs(float(table.mean())) < 1e-3
    assert abs(float(table.std()) - math.sqrt(4.0 + 1 / 12)) < 1e-3  # rounding adds 1/12
    images = []
    for noise in (0.0, 2.0):
        settings = SensorSettings(camera_width=80, camera_height=60, camera_noise=noise)
        message = make_sim("vrc_task_2", "1", sensors=settings).sensors.compute("camera", 0.0)
        images.append(np.frombuffer(message["data"], dtype=np.uint8).astype(float))
    clean, noisy = images
    inside = (clean > 10) & (clean < 245)  # away from the clipping at 0 and 255
    assert 1.8 < float(np.std((noisy - clean)[inside])) < 2.2


def test_the_camera_draws_the_ground_as_tinyrenderer_did(make_sim) -> None:
    # TinyRenderer draws every body but the ground plane, which `_ground` draws by its depth
    # buffer: the image must be the one TinyRenderer gives with the plane, but for the plane's
    # square edges (a pixel either way) and the aliased squares near the horizon.
    settings = SensorSettings(camera_width=160, camera_height=120, camera_noise=0.0)
    sim = make_sim("vrc_task_2", "1", sensors=settings)  # gates, mud pit, rubble, hill ahead
    client, ground, sensors = sim.client, sim.scene.ground, sim.sensors
    head, rotation = sensors._head_pose()
    eye = head + rotation @ LEFT_EYE_IN_HEAD
    rgba = client.getVisualShapeData(ground)[0][7]
    drawn = np.frombuffer(sensors._render(eye, rotation, np.random.default_rng(0)), np.uint8)
    assert client.getVisualShapeData(ground)[0][7] == rgba  # the plane's own look is kept
    view = client.computeViewMatrix(
        eye.tolist(), (eye + rotation[:, 0]).tolist(), rotation[:, 2].tolist()
    )
    tiny = np.asarray(
        client.getCameraImage(
            160, 120, view, sensors.projection, renderer=pybullet.ER_TINY_RENDERER
        )[2],
        dtype=np.uint8,
    ).reshape(120, 160, 4)[:, :, :3]
    same = (drawn.reshape(120, 160, 3) == tiny).all(axis=2)
    assert same.mean() > 0.85
    assert same[90:].mean() > 0.95  # nearer than the horizon: the edges alone differ
