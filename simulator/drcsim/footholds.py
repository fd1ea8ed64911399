"""Footholds from a height map: where a planned step may go, and how a sole lies on a hill.

Rays cast straight down over each planned sole stand in for the height map a robot builds
from its lidar (no occlusion, no noise): a foothold moves to where the sole lies flat, on
the ground or wholly on one block's top, the whole plan's footholds chosen at once; the swing
passes above what stands on its way; on a hill a sole rests on the ground's upper hull.
"""

from __future__ import annotations

import itertools
import math

import numpy as np

from drcsim.gait import ZMP_AHEAD, Foothold, Swing, rotation
from drcsim.scene import Scene

# A foothold on uneven ground moves to the nearest spot where the sole (and a margin round it)
# lies flat, on the ground or wholly on one block's top, never across an edge: the height of
# what stands above the ground's shape is sampled every PLACE_GRID m round the planned spot
# (rays cast down, in the foot's frame) and the sole slid over it, PLACE_ALONG m either way
# along its heading and up to PLACE_OUT m outwards, within PLACE_FLAT (m) of height spread.
PLACE_GRID = 0.025
PLACE_SOLE = (-0.13, 0.22, 0.08)  # m: heel and toe from the ankle, half-width (margins in)
PLACE_ALONG = 12  # grid steps either way along the heading (0.3 m)...
PLACE_OUT = 6  # ...and across: outwards, away from the other foot (0.15 m)...
PLACE_IN = 2  # ...or inwards (0.05 m), keeping the feet MIN_WIDTH apart
PLACE_FLAT = 0.01
PLACE_ON_BLOCK = 0.1  # m of shift a block's top costs over the ground (a block may shift)
MIN_WIDTH = 0.14  # m between the ankles, at the least (the soles are 0.13 m wide)
MAX_STRIDE = 0.5  # m a foothold may lie ahead of the other foot (unless planned further)
PLACE_RHYTHM = 0.5  # cost per m a stride differs from the plan's
ACROSS_EDGE = 1.0  # cost of a sole across an edge (only where nothing flat is in reach)
UNREACHABLE = 100.0
SWING_MARGIN = 0.03  # m the sole passes above what stands on its way
SOLE_SAMPLES = tuple(-0.09 + 0.26 * k / 8 for k in range(9))  # m along the sole, heel to toe
SLOPE_SPAN = 0.1  # m either side of a foot over which the slope under it is taken


class Footholds:
    """Chooses footholds and sole orientations on a scene's ground, blocks and hills."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene

    def place(self, feet: dict[str, Foothold], steps: list[tuple[str, Foothold]]) -> list[Foothold]:
        """Return where each planned step goes: the sole flat (not across an edge), near plan.

        Each step may move to spots round its planned foothold where the sole lies flat; the
        cheapest sequence (least moved, strides within reach) is chosen by dynamic
        programming over the whole plan.
        """
        previous = [(0.0, feet["right" if steps[0][0] == "left" else "left"])] if steps else []
        prev_cost = np.zeros(1)
        back: list[np.ndarray] = []
        choices: list[list[Foothold]] = []
        planned_prev = previous[0][1] if previous else None
        for side, foot in steps:
            options = self._candidates(foot, side)
            holds = [hold for _, hold in options]
            cost = np.array([c for c, _ in options])
            c, s = math.cos(foot.yaw), math.sin(foot.yaw)
            assert planned_prev is not None
            planned = c * (foot.x - planned_prev.x) + s * (foot.y - planned_prev.y)
            px = np.array([h.x for h in choices[-1]]) if choices else np.array([previous[0][1].x])
            py = np.array([h.y for h in choices[-1]]) if choices else np.array([previous[0][1].y])
            hx, hy = np.array([h.x for h in holds]), np.array([h.y for h in holds])
            ahead = c * (hx[None, :] - px[:, None]) + s * (hy[None, :] - py[:, None])
            sign = 1.0 if side == "left" else -1.0
            width = sign * (c * (hy[None, :] - py[:, None]) - s * (hx[None, :] - px[:, None]))
            reach = (ahead >= min(-0.05, planned)) & (ahead <= max(MAX_STRIDE, planned))
            reach &= width >= MIN_WIDTH
            total = prev_cost[:, None] + cost[None, :] + PLACE_RHYTHM * np.abs(ahead - planned)
            total = np.where(reach, total, total + UNREACHABLE)
            back.append(np.argmin(total, axis=0))
            prev_cost = total[back[-1], np.arange(len(holds))]
            choices.append(holds)
            planned_prev = foot
        if not steps:
            return []
        pick = int(np.argmin(prev_cost))
        chosen = []
        for holds, links in zip(reversed(choices), reversed(back), strict=True):
            chosen.append(holds[pick])
            pick = int(links[pick])
        return chosen[::-1]

    def _candidates(self, foot: Foothold, side: str) -> list[tuple[float, Foothold]]:
        """Return (cost, foothold) for spots round a planned one: flat ones cheap, else dear."""
        c, s = math.cos(foot.yaw), math.sin(foot.yaw)
        grid = PLACE_GRID
        heel, toe, half = PLACE_SOLE
        rows = round((toe - heel) / grid) + 1  # samples along the sole...
        cols = 2 * round(half / grid) + 1  # ...and across it
        along = heel - PLACE_ALONG * grid + grid * np.arange(rows + 2 * PLACE_ALONG)
        across = grid * np.arange(-(cols // 2) - PLACE_OUT, cols // 2 + PLACE_OUT + 1)
        if side == "right":
            across = -across  # outwards first, whichever the side
        heights = np.array(self._heights_at(foot.x, foot.y, c, s, along, across))
        heights = heights.reshape(len(along), len(across))
        if not heights.any():  # nothing but the ground's own shape: as planned
            return [(0.0, self._on_hill(foot))]
        options = []
        for k in range(2 * PLACE_ALONG + 1):
            shift = (k - PLACE_ALONG) * grid
            for out in range(-PLACE_IN, PLACE_OUT + 1):
                middle = len(across) // 2 + out
                window = heights[k : k + rows, middle - cols // 2 : middle + cols // 2 + 1]
                top, spread = float(window.max()), float(window.max() - window.min())
                side_shift = float(across[middle] - across[len(across) // 2])
                x, y = foot.x + c * shift - s * side_shift, foot.y + s * shift + c * side_shift
                here = self._on_hill(Foothold(x, y, self.scene.ground_height(x, y) + top, foot.yaw))
                cost = abs(shift) + 2 * abs(out) * grid
                if top > PLACE_FLAT:
                    cost += PLACE_ON_BLOCK
                if spread > PLACE_FLAT:
                    cost += ACROSS_EDGE + 10 * spread
                options.append((cost, here))
        return options

    def _on_hill(self, foot: Foothold) -> Foothold:
        """Return the foothold at the height of its sole resting on a hill, if on one."""
        patch = self.scene.terrain_at(foot.x, foot.y)
        if patch is None or patch.kind != "hill":
            return foot
        ground = self.scene.ground_height(foot.x, foot.y)
        return Foothold(foot.x, foot.y, foot.z - ground + self._resting(foot)[1], foot.yaw)

    def floor(self, swing: Swing) -> tuple[float, ...]:
        """Return the lowest the sole may pass along its way: over what stands there."""
        a, b = swing.start, swing.end
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        floor = [-math.inf]
        for k in range(1, 10):
            x, y = a.x + (b.x - a.x) * k / 10, a.y + (b.y - a.y) * k / 10
            block = max(self._heights(x, y, c, s))  # above the ground's own shape (a hill)
            top = self.scene.ground_height(x, y) + block
            low = min(a.z, b.z) + PLACE_FLAT
            floor.append(top + SWING_MARGIN if block > PLACE_FLAT and top > low else -math.inf)
        return (*floor, -math.inf)

    def _heights(self, x: float, y: float, c: float, s: float) -> list[float]:
        """Return what stands above the ground's shape over a sole and a margin round it."""
        heel, toe, half = PLACE_SOLE
        return self._heights_at(x, y, c, s, np.linspace(heel, toe, 5), np.linspace(-half, half, 5))

    def _heights_at(
        self, x: float, y: float, c: float, s: float, along: np.ndarray, across: np.ndarray
    ) -> list[float]:
        """Return what stands above the ground's shape at a grid (in a foot's frame) round x, y."""
        starts, ends = [], []
        for a in along:
            for b in across:
                px, py = x + c * a - s * b, y + s * a + c * b
                starts.append((px, py, 0.5))
                ends.append((px, py, -0.05))
        heights = []
        for (px, py, _), hit in zip(
            starts, self.scene.client.rayTestBatch(starts, ends), strict=True
        ):
            if hit[0] >= 0 and hit[0] != self.scene.robot:
                heights.append(max(0.0, float(hit[3][2]) - self.scene.ground_height(px, py)))
            else:
                heights.append(0.0)
        return heights

    def sole(self, foot: Foothold) -> np.ndarray:
        """Return the foot's rotation lying on the slope under it (a hill's ramp)."""
        patch = self.scene.terrain_at(foot.x, foot.y)
        if patch is None or patch.kind != "hill":
            return rotation(0.0, 0.0, foot.yaw)
        c, s, d = math.cos(foot.yaw), math.sin(foot.yaw), SLOPE_SPAN
        height = self.scene.ground_height
        along = self._resting(foot)[0]
        across = (
            height(foot.x - s * d, foot.y + c * d) - height(foot.x + s * d, foot.y - c * d)
        ) / (2 * d)
        return rotation(math.atan(across), -math.atan(along), foot.yaw)

    def _resting(self, foot: Foothold) -> tuple[float, float]:
        """Return the slope along a sole resting on a hill, and its height at the ankle.

        The sole rests on the ground's upper hull under it, on the stretch under its
        mid-sole: across a crest it lies on the ramp its load is on and overhangs the other
        (a sole at the mean slope stood on the crest's edge and spun about it), across the
        foot of a ramp on heel and toe.
        """
        c, s = math.cos(foot.yaw), math.sin(foot.yaw)
        height = self.scene.ground_height
        points = [(u, height(foot.x + c * u, foot.y + s * u)) for u in SOLE_SAMPLES]
        hull: list[tuple[float, float]] = []
        for point in points:  # the upper hull, left to right
            while (
                len(hull) >= 2
                and (
                    (hull[-1][0] - hull[-2][0]) * (point[1] - hull[-2][1])
                    - (hull[-1][1] - hull[-2][1]) * (point[0] - hull[-2][0])
                )
                >= 0
            ):
                hull.pop()
            hull.append(point)
        for (u1, h1), (u2, h2) in itertools.pairwise(hull):
            if u2 >= ZMP_AHEAD or (u2, h2) == hull[-1]:
                slope = (h2 - h1) / (u2 - u1)
                return slope, h1 - slope * u1
        return 0.0, points[0][1]
