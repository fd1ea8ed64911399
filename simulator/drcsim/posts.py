"""Where the robot is, by the gates' posts its lidar sees: a team's code, not the simulator's.

It uses only the lidar message and the course briefing as the README gives them: returns at
a post's height, grouped into posts, matched to the briefing's posts; the shift that lines
them up corrects the robot's drifting estimate (`state`).
"""

from __future__ import annotations

import math
from array import array
from typing import Any

# The lidar (README, Sensors): from this point in the head frame, its scan plane the head's x-y
# plane rolled about the head's x axis by the spindle angle.
LIDAR_IN_HEAD = (0.16, 0.0, 0.12)
# Lidar returns this high over the ground (m) are the gates' posts: the vehicle is lower (its
# cage about 1.5 m), the robot's own body is nearer than POST_NEAREST and the ground far below.
POST_BAND = (1.6, 2.3)
POST_NEAREST = 0.8
# How far apart (m) two returns may be and still be on the same post (0.15 m across).
POST_CLUSTER = 0.3
# Returns on one post for it to count, and how near (m) a post must fall to where the
# briefing's gate puts it once the estimate is corrected (gates are off by up to 0.25 m).
POST_MIN_RETURNS = 4
POST_MATCH = 0.45


def _rotation(q: list[float]) -> tuple[tuple[float, float, float], ...]:
    """The rotation matrix (rows) of a quaternion [x, y, z, w]."""
    x, y, z, w = q
    return (
        (1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)),
        (2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)),
        (2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)),
    )


def _apply(
    rotation: tuple[tuple[float, float, float], ...], p: tuple[float, float, float]
) -> tuple[float, float, float]:
    r0, r1, r2 = rotation
    return (
        r0[0] * p[0] + r0[1] * p[1] + r0[2] * p[2],
        r1[0] * p[0] + r1[1] * p[1] + r1[2] * p[2],
        r2[0] * p[0] + r2[1] * p[1] + r2[2] * p[2],
    )


def post_returns(scan: dict[str, Any], pelvis: dict[str, Any]) -> list[tuple[float, float]]:
    """Where (x, y) a lidar scan met something in POST_BAND, by the pelvis estimate `pelvis`.

    Each return goes from the lidar (README: LIDAR_IN_HEAD in the head frame, the scan plane
    rolled about the head's x axis by `spindle`) through `head_in_pelvis` and the estimated
    pelvis pose to the world: off from the truth by whatever the estimate is off.
    """
    ranges = array("f", scan["ranges"])
    head = scan["head_in_pelvis"]
    head_r, head_t = _rotation(head["orientation"]), head["position"]
    pelvis_r, pelvis_t = _rotation(pelvis["orientation"]), pelvis["position"]
    count = len(ranges)
    a0, a1 = scan["angle_min"], scan["angle_max"]
    cos_s, sin_s = math.cos(scan["spindle"]), math.sin(scan["spindle"])
    far = scan["range_max"] - 0.05
    found = []
    for i, r in enumerate(ranges):
        if r < POST_NEAREST or r > far:
            continue
        a = a0 + (a1 - a0) * i / (count - 1)
        ca, sa = math.cos(a), math.sin(a)
        in_head = (
            LIDAR_IN_HEAD[0] + r * ca,
            LIDAR_IN_HEAD[1] + r * sa * cos_s,
            LIDAR_IN_HEAD[2] + r * sa * sin_s,
        )
        in_pelvis = _apply(head_r, in_head)
        in_pelvis = (in_pelvis[0] + head_t[0], in_pelvis[1] + head_t[1], in_pelvis[2] + head_t[2])
        x, y, z = _apply(pelvis_r, in_pelvis)
        if POST_BAND[0] <= z + pelvis_t[2] <= POST_BAND[1]:
            found.append((x + pelvis_t[0], y + pelvis_t[1]))
    return found


def clusters(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """The middles of the groups of points within POST_CLUSTER of each other (the posts)."""
    groups: list[list[tuple[float, float]]] = []
    for p in sorted(points):
        for group in groups:
            if any(math.dist(p, q) <= POST_CLUSTER for q in group[-20:]):
                group.append(p)
                break
        else:
            groups.append([p])
    return [
        (sum(p[0] for p in g) / len(g), sum(p[1] for p in g) / len(g))
        for g in groups
        if len(g) >= POST_MIN_RETURNS
    ]


def gate_posts(gates: dict[str, Any]) -> list[tuple[float, float]]:
    """Where the briefing puts each gate's two posts (either side of its opening)."""
    posts = []
    for gate in gates.values():
        gx, gy, gyaw = gate["pose"]
        half = gate["width"] / 2 + 0.075
        posts += [(gx - half * math.sin(gyaw), gy + half * math.cos(gyaw))]
        posts += [(gx + half * math.sin(gyaw), gy - half * math.cos(gyaw))]
    return posts


def post_correction(
    seen: list[tuple[float, float]], posts: list[tuple[float, float]]
) -> tuple[float, float] | None:
    """The shift that puts the posts seen (by the estimate) where the briefing has them.

    Every pairing of a post seen with a post of the briefing proposes a shift; the one most
    other pairings agree with (within POST_MATCH) wins, the smaller shift on a tie; the
    answer is the mean of the agreeing shifts. None when nothing is seen, or when no shift
    is backed by two posts (one post alone cannot say which it is).
    """
    shifts = [((p[0] - s[0], p[1] - s[1]), i) for i, s in enumerate(seen) for p in posts]
    best: list[tuple[float, float]] = []
    best_key: tuple[int, float] | None = None
    for shift, _ in shifts:
        agree = [(t, i) for t, i in shifts if math.dist(t, shift) <= POST_MATCH]
        key = (-len({i for _, i in agree}), math.hypot(*shift))
        if best_key is None or key < best_key:
            best, best_key = [t for t, _ in agree], key
    if best_key is None or -best_key[0] < 2:
        return None
    return sum(t[0] for t in best) / len(best), sum(t[1] for t in best) / len(best)
