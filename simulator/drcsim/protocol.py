"""The command channel's message format: msgpack maps, checked strictly before use."""

from __future__ import annotations

import math
from typing import Any

import msgpack

from drcsim.driving import DIRECTIONS
from drcsim.errors import ProtocolError
from drcsim.models.humanoid import ALL_JOINTS, JOINT_NAMES

MAX_MESSAGE_BYTES = 64 * 1024
MAX_STEPS = 10_000
HANDS = ("left", "right")
FRAMES = ("world", "pelvis")
OPS = ("hello", "state", "step", "joints", "behaviour", "stop")
# Behaviour name -> its parameters and their kinds ("hand", "vec3", "float", "bool", "direction").
BEHAVIOURS: dict[str, dict[str, str]] = {
    "none": {},
    "stand": {},
    "walk": {
        "pose": "vec3",
        "step_length": "float?",
        "step_height": "float?",
        "step_time": "float?",
        "double_support": "float?",
        "stance_width": "float?",
    },
    "reach": {"hand": "hand", "target": "vec3", "tool": "bool?", "frame": "frame?"},
    "arm_rest": {"hand": "hand"},
    "grasp": {"hand": "hand"},
    "release": {"hand": "hand"},
    "enter_vehicle": {},
    "exit_vehicle": {},
    "drive": {
        "steering_wheel": "float?",
        "throttle": "float?",
        "brake": "float?",
        "hand_brake": "bool?",
        "direction": "direction?",
    },
    "turn_valve": {"hand": "hand", "angle": "float?"},
}
_KNOWN_JOINTS = frozenset(JOINT_NAMES)
# The documented range of each numeric behaviour parameter: a value outside it is refused
# with the range, never clamped (a team must learn that its step_length of 100 is no gait).
RANGES: dict[str, tuple[float, float, str]] = {
    "walk.step_length": (0.02, 0.5, "m"),
    "walk.step_height": (0.01, 0.2, "m"),
    "walk.step_time": (0.3, 2.0, "s"),
    "walk.double_support": (0.05, 1.0, "s"),
    "walk.stance_width": (0.12, 0.4, "m"),
    "drive.steering_wheel": (-3.0, 3.0, "rad"),
    "drive.throttle": (0.0, 1.0, ""),
    "drive.brake": (0.0, 1.0, ""),
    "turn_valve.angle": (-4 * math.pi, 4 * math.pi, "rad"),
}
JOINT_RANGES = {spec.name: (spec.lower, spec.upper) for spec in ALL_JOINTS}


def _in_range(value: float, where: str, low: float, high: float, unit: str = "") -> float:
    if not low <= value <= high:
        unit = f" {unit}" if unit else ""
        raise ProtocolError(f"{where} must be in {low:g}..{high:g}{unit}, not {value:g}")
    return value


def _finite(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ProtocolError(f"{where} must be a finite number")
    return float(value)


def _check_param(kind: str, value: Any, where: str) -> Any:
    kind = kind.rstrip("?")
    if kind == "hand":
        if value not in HANDS:
            raise ProtocolError(f"{where} must be one of {HANDS}")
        return value
    if kind == "vec3":
        if not isinstance(value, list | tuple) or len(value) != 3:
            raise ProtocolError(f"{where} must be a list of 3 numbers")
        return [_finite(v, where) for v in value]
    if kind == "float":
        return _finite(value, where)
    if kind == "bool":
        if not isinstance(value, bool):
            raise ProtocolError(f"{where} must be true or false")
        return value
    if kind == "frame":
        if value not in FRAMES:
            raise ProtocolError(f"{where} must be one of {FRAMES}")
        return value
    if value not in DIRECTIONS:
        raise ProtocolError(f"{where} must be one of {sorted(DIRECTIONS)}")
    return value


def _joint_map(value: Any, where: str, arity: int = 1) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise ProtocolError(f"{where} must be a map of joint name to value")
    checked: dict[str, Any] = {}
    for name, item in value.items():
        if name not in _KNOWN_JOINTS:
            raise ProtocolError(f"{where}: unknown joint {name!r}")
        if arity == 1:
            checked[name] = _finite(item, f"{where}.{name}")
            if where == "position":
                checked[name] = _in_range(checked[name], f"position.{name}", *JOINT_RANGES[name])
        else:
            if not isinstance(item, list | tuple) or len(item) != arity:
                raise ProtocolError(f"{where}.{name} must be {arity} numbers")
            numbers = [_finite(v, f"{where}.{name}") for v in item]
            if any(v < 0 for v in numbers):
                raise ProtocolError(f"{where}.{name}: gains must not be negative")
            checked[name] = numbers
    return checked


def check_command(message: Any) -> dict[str, Any]:
    """Return a cleaned copy of a decoded command; raise ProtocolError if it is malformed."""
    if not isinstance(message, dict) or not all(isinstance(k, str) for k in message):
        raise ProtocolError("a command must be a map with string keys")
    op = message.get("op")
    if op not in OPS:
        raise ProtocolError(f"unknown op {op!r} (known: {', '.join(OPS)})")
    clean: dict[str, Any] = {"op": op}
    if "id" in message:
        if not isinstance(message["id"], int) or isinstance(message["id"], bool):
            raise ProtocolError("id must be an integer")
        clean["id"] = message["id"]
    if op == "step":
        steps = message.get("steps", 1)
        if not isinstance(steps, int) or isinstance(steps, bool) or not 1 <= steps <= MAX_STEPS:
            raise ProtocolError(f"steps must be an integer in 1..{MAX_STEPS}")
        clean["steps"] = steps
    elif op == "joints":
        for key, arity in (("position", 1), ("torque", 1), ("gains", 3)):
            if key in message:
                clean[key] = _joint_map(message[key], key, arity)
        if len(clean) == 1 + ("id" in clean):
            raise ProtocolError("joints needs position, torque or gains")
    elif op == "behaviour":
        name = message.get("name")
        if name not in BEHAVIOURS:
            raise ProtocolError(f"unknown behaviour {name!r} (known: {', '.join(BEHAVIOURS)})")
        clean["name"] = name
        params = BEHAVIOURS[name]
        for key in message:
            if key not in ("op", "id", "name") and key not in params:
                raise ProtocolError(f"behaviour {name} takes no parameter {key!r}")
        for key, kind in params.items():
            if key in message:
                where = f"{name}.{key}"
                clean[key] = _check_param(kind, message[key], where)
                if where in RANGES:
                    clean[key] = _in_range(clean[key], where, *RANGES[where])
            elif not kind.endswith("?"):
                raise ProtocolError(f"behaviour {name} needs {key!r}")
    return clean


def decode_command(raw: bytes) -> dict[str, Any]:
    """Decode and check one command frame; raise ProtocolError on anything wrong."""
    if len(raw) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {len(raw)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        message = msgpack.unpackb(raw, raw=False, strict_map_key=True)
    except (
        ValueError,
        TypeError,
        msgpack.ExtraData,
        msgpack.FormatError,
        msgpack.StackError,
    ) as exc:
        raise ProtocolError(f"not a msgpack message: {exc}") from exc
    try:
        return check_command(message)
    except ProtocolError as exc:
        # The reply carries the id, so a client waiting for it gets the error, not a timeout.
        ident = message.get("id") if isinstance(message, dict) else None
        if isinstance(ident, int) and not isinstance(ident, bool):
            exc.request_id = ident
        raise


def encode(message: dict[str, Any]) -> bytes:
    """Encode a message for the wire."""
    return msgpack.packb(message, use_bin_type=True)
