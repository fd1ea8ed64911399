"""Mud as the VRC's drcsim modelled it (Gazebo's MudPlugin): links sink through its surface
to a firm bottom, and the mud drags at them while they are in it.

The MudPlugin made the mud box's surface collide without contact for the robot's links and,
while a link touched the mud, held it with a joint at the contact point whose soft erp/cfm
came from a `stiffness` and a `damping`; the joint's anchor moved to the contact point at
every update, so what held the link was mostly viscous drag. Here the mud has no collision
shape at all (nothing stands on its surface), the pit's bottom is a rigid box with the mud's
friction, and each robot link in the mud gets a drag force against its velocity, `damping`
N s/m for a leg in to the mud's full depth, in proportion to how much of the link is in.
"""

from __future__ import annotations

from dataclasses import dataclass

from drcsim._bullet import BulletClient, pybullet

REFRESH_STEPS = 10  # physics steps between looks at which links are in the mud (100 Hz)
# Share of a link's velocity the drag may take away in one physics step: explicit damping
# at 1 kHz stays purely resistive (it never reverses a link's motion) however light the link.
MAX_VELOCITY_SHARE = 0.5
# Links with less of the depth in the mud than this (an ankle's 2 mm talus) are not worth
# their cost: each dragged link costs an engine call per physics step.
MIN_IMMERSION = 0.05
WORLD_FRAME = pybullet.WORLD_FRAME


@dataclass(frozen=True)
class MudPit:
    """A mud pit: its rectangle, its firm bottom and surface heights, its drag."""

    lower: tuple[float, float]
    upper: tuple[float, float]
    bottom: float  # m above the ground: where feet stand
    surface: float  # m above the ground: the mud's top
    damping: float  # N s/m on a leg in to the full depth

    def immersion(self, lower: tuple[float, ...], upper: tuple[float, ...]) -> float:
        """Return the share of the depth that a box (an AABB) fills of the mud, 0..1 or more."""
        depth = self.surface - self.bottom
        height = min(self.surface, upper[2]) - max(self.bottom, lower[2])
        if height <= 0.0 or depth <= 0.0:
            return 0.0
        # Only the part of the box over the pit is in it (a foot across the rim).
        area = 1.0
        for axis in (0, 1):
            size = upper[axis] - lower[axis]
            inside = min(self.upper[axis], upper[axis]) - max(self.lower[axis], lower[axis])
            area *= max(0.0, min(1.0, inside / size)) if size > 0.0 else 1.0
        return area * height / depth


class MudDrag:
    """Drags at the robot's links that are in the mud: a force against each one's velocity."""

    def __init__(
        self, client: BulletClient, body: int, pits: list[MudPit], timestep: float
    ) -> None:
        self.client, self.body, self.pits = client, body, pits
        count = client.getNumJoints(body)
        # Never more drag than takes MAX_VELOCITY_SHARE of a link's own momentum in a step.
        self.bounds = {
            link: MAX_VELOCITY_SHARE * client.getDynamicsInfo(body, link)[0] / timestep
            for link in range(-1, count)
        }
        self.dragged: list[tuple[int, float]] = []  # (link, N s/m); -1 is the base

    def refresh(self) -> None:
        """Find the links in the mud and the drag on each (by how deep it is in)."""
        dragged: list[tuple[int, float]] = []
        for pit in self.pits:
            found = self.client.getOverlappingObjects(
                [pit.lower[0], pit.lower[1], pit.bottom], [pit.upper[0], pit.upper[1], pit.surface]
            )
            for body, link in found or ():
                if body != self.body:
                    continue
                lower, upper = self.client.getAABB(body, link)
                share = pit.immersion(lower, upper)
                if share >= MIN_IMMERSION:
                    dragged.append((link, min(pit.damping * share, self.bounds[link])))
        self.dragged = dragged

    def apply(self, step: int) -> None:
        """Set this physics step's drag forces (a step's external forces last one step)."""
        if self.pits and step % REFRESH_STEPS == 0:
            self.refresh()
        if not self.dragged:
            return
        client, body = self.client, self.body
        links = [link for link, _ in self.dragged if link >= 0]
        states = iter(client.getLinkStates(body, links, computeLinkVelocity=1) if links else [])
        for link, scale in self.dragged:
            if link < 0:
                where = client.getBasePositionAndOrientation(body)[0]
                vx, vy, vz = client.getBaseVelocity(body)[0]
            else:
                state = next(states)
                where, (vx, vy, vz) = state[0], state[6]
            client.applyExternalForce(
                body, link, (-scale * vx, -scale * vy, -scale * vz), where, WORLD_FRAME
            )
