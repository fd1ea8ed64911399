"""A tiny URDF writer: links with primitive shapes and joints, rendered to XML text."""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

Vec3 = tuple[float, float, float]
ZERO: Vec3 = (0.0, 0.0, 0.0)


def _v(values: Vec3) -> str:
    return " ".join(f"{value:.6g}" for value in values)


@dataclass(frozen=True)
class Shape:
    """A primitive: box (size), sphere (radius), cylinder or capsule (radius, length)."""

    kind: str
    size: Vec3 = ZERO
    radius: float = 0.0
    length: float = 0.0
    xyz: Vec3 = ZERO
    rpy: Vec3 = ZERO

    def geometry_xml(self) -> str:
        """Return the <geometry> element of this shape."""
        if self.kind == "box":
            inner = f"<box size={quoteattr(_v(self.size))}/>"
        elif self.kind == "sphere":
            inner = f'<sphere radius="{self.radius:.6g}"/>'
        else:
            inner = f'<{self.kind} radius="{self.radius:.6g}" length="{self.length:.6g}"/>'
        return f"<geometry>{inner}</geometry>"

    def origin_xml(self) -> str:
        """Return the <origin> element placing this shape in its link."""
        return f"<origin xyz={quoteattr(_v(self.xyz))} rpy={quoteattr(_v(self.rpy))}/>"


def box(sx: float, sy: float, sz: float, xyz: Vec3 = ZERO, rpy: Vec3 = ZERO) -> Shape:
    """Return a box shape."""
    return Shape("box", size=(sx, sy, sz), xyz=xyz, rpy=rpy)


def cylinder(radius: float, length: float, xyz: Vec3 = ZERO, rpy: Vec3 = ZERO) -> Shape:
    """Return a cylinder along the local z axis."""
    return Shape("cylinder", radius=radius, length=length, xyz=xyz, rpy=rpy)


def capsule(radius: float, length: float, xyz: Vec3 = ZERO, rpy: Vec3 = ZERO) -> Shape:
    """Return a capsule along the local z axis."""
    return Shape("capsule", radius=radius, length=length, xyz=xyz, rpy=rpy)


def sphere(radius: float, xyz: Vec3 = ZERO) -> Shape:
    """Return a sphere."""
    return Shape("sphere", radius=radius, xyz=xyz)


@dataclass
class Link:
    """A rigid link: mass, centre of mass, inertia from its first shape, collision + visual."""

    name: str
    mass: float
    shapes: list[Shape] = field(default_factory=list)
    rgba: tuple[float, float, float, float] = (0.6, 0.6, 0.6, 1.0)
    collide: bool = True
    com: Vec3 | None = None

    def inertia(self) -> Vec3:
        """Return principal moments from the first shape (good enough for primitives)."""
        if not self.shapes or self.mass <= 0.0:
            return (1e-4, 1e-4, 1e-4)
        s = self.shapes[0]
        m = self.mass
        if s.kind == "box":
            x, y, z = s.size
            return (m * (y * y + z * z) / 12, m * (x * x + z * z) / 12, m * (x * x + y * y) / 12)
        if s.kind == "sphere":
            i = 0.4 * m * s.radius**2
            return (i, i, i)
        r, h = s.radius, s.length + (2 * s.radius if s.kind == "capsule" else 0.0)
        side = m * (3 * r * r + h * h) / 12
        return (side, side, 0.5 * m * r * r)

    def to_xml(self) -> str:
        """Return the <link> element."""
        com = self.com or (self.shapes[0].xyz if self.shapes else ZERO)
        ixx, iyy, izz = (max(i, 1e-5) for i in self.inertia())
        parts = [f"<link name={quoteattr(self.name)}>"]
        parts.append(
            f'<inertial><origin xyz={quoteattr(_v(com))}/><mass value="{self.mass:.6g}"/>'
            f'<inertia ixx="{ixx:.6g}" iyy="{iyy:.6g}" izz="{izz:.6g}" ixy="0" ixz="0" iyz="0"/>'
            "</inertial>"
        )
        colour = _v(self.rgba[:3]) + f" {self.rgba[3]:.3g}"
        for shape in self.shapes:
            parts.append(
                f"<visual>{shape.origin_xml()}{shape.geometry_xml()}"
                f'<material name="m"><color rgba={quoteattr(colour)}/></material></visual>'
            )
            if self.collide:
                parts.append(f"<collision>{shape.origin_xml()}{shape.geometry_xml()}</collision>")
        parts.append("</link>")
        return "\n".join(parts)


@dataclass
class Joint:
    """A joint between two links with its limits (position, velocity, effort)."""

    name: str
    kind: str
    parent: str
    child: str
    xyz: Vec3 = ZERO
    axis: Vec3 = (0.0, 0.0, 1.0)
    lower: float = 0.0
    upper: float = 0.0
    velocity: float = 1.0
    effort: float = 0.0
    damping: float = 0.0
    rpy: Vec3 = ZERO

    def to_xml(self) -> str:
        """Return the <joint> element."""
        parts = [
            f"<joint name={quoteattr(self.name)} type={quoteattr(self.kind)}>",
            f"<parent link={quoteattr(self.parent)}/><child link={quoteattr(self.child)}/>",
            f"<origin xyz={quoteattr(_v(self.xyz))} rpy={quoteattr(_v(self.rpy))}/>",
        ]
        if self.kind != "fixed":
            parts.append(f"<axis xyz={quoteattr(_v(self.axis))}/>")
            parts.append(
                f'<limit lower="{self.lower:.6g}" upper="{self.upper:.6g}" '
                f'velocity="{self.velocity:.6g}" effort="{self.effort:.6g}"/>'
            )
            parts.append(f'<dynamics damping="{self.damping:.6g}" friction="0"/>')
        parts.append("</joint>")
        return "\n".join(parts)


@dataclass
class Robot:
    """A URDF model: its links (the first is the base) and joints."""

    name: str
    links: list[Link] = field(default_factory=list)
    joints: list[Joint] = field(default_factory=list)

    def add(self, link: Link, joint: Joint | None = None) -> Link:
        """Append a link and the joint that attaches it; return the link."""
        self.links.append(link)
        if joint is not None:
            self.joints.append(joint)
        return link

    def to_xml(self) -> str:
        """Return the whole URDF document."""
        # pybullet's XML reader fails on very long lines: one element per line.
        body = "\n".join(link.to_xml() for link in self.links)
        body += "\n" + "\n".join(joint.to_xml() for joint in self.joints)
        return f'<?xml version="1.0"?>\n<robot name={quoteattr(self.name)}>\n{body}\n</robot>\n'

    def write(self, directory: Path) -> Path:
        """Write the URDF under a content-addressed name (safe to share between runs)."""
        text = self.to_xml()
        digest = hashlib.sha256(text.encode()).hexdigest()[:16]
        path = directory / f"{self.name}-{digest}.urdf"
        if not path.exists():
            directory.mkdir(parents=True, exist_ok=True)
            partial = path.with_name(f"{path.name}.{os.getpid()}.tmp")
            partial.write_text(text)
            partial.replace(path)
        return path
