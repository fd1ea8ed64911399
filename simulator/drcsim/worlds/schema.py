"""The world document's schema: what a world file may say, checked before anything is built.

A world document is the JSON a world file holds (see the shipped `vrc_task_*.json`). Every
orchestrator that stores or edits worlds (CloudSim does) validates with `check_document`
rather than re-declaring the format, so a document accepted there is one `drcsim serve
--world-file` loads. Standard library only: no physics is imported.
"""

from __future__ import annotations

import math
import re
from typing import Any

from drcsim.errors import WorldError

MODELS = ("gate", "vehicle", "table", "hose", "standpipe")
# terrain kind -> the fields scene.py reads (besides id, kind, min, max)
TERRAIN_FIELDS = {
    "mud": ("friction", "depth", "damping"),
    "rubble": ("blocks", "max_height", "friction"),
    "hill": ("rise", "slope"),
}
TERRAIN_OPTIONAL = {"mud": (), "rubble": ("density",), "hill": ("friction",)}  # with defaults
BODIES = ("robot", "vehicle", "hose")
QUANTITY_CONDITIONS = ("at_least", "at_most", "increase")
TOP_REQUIRED = ("name", "title", "time_limit_s", "ground", "robot", "objects", "terrain")
TOP_KEYS = (*TOP_REQUIRED, "checkpoints", "configs", "assists")
CONFIG_KEYS = ("seed", "robot", "ground", "objects", "terrain")
NAME = re.compile(r"[a-z][a-z0-9_]{0,63}")
MAX_DEPTH = 8
MAX_ITEMS = 100  # objects, terrain patches, checkpoints
MAX_SEED = 2**31 - 1


def _fail(where: str, message: str) -> WorldError:
    return WorldError(f"{where}: {message}")


def _number(value: Any, where: str, minimum: float | None = None) -> float:
    try:
        number = float(value) if not isinstance(value, bool | str) else math.nan
    except (TypeError, ValueError, OverflowError):
        number = math.nan
    if not math.isfinite(number):
        raise _fail(where, f"must be a number, not {str(value)[:40]!r}")
    if minimum is not None and number < minimum:
        raise _fail(where, f"must be at least {minimum}, not {number}")
    return number


def _mapping(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise _fail(where, "must be an object")
    return value


def _text(value: Any, where: str, limit: int = 200) -> str:
    if not isinstance(value, str) or not value.strip() or len(value) > limit:
        raise _fail(where, f"must be a non-empty text of at most {limit} characters")
    return value


def _vector(value: Any, where: str, size: int) -> None:
    if not isinstance(value, list) or len(value) != size:
        raise _fail(where, f"must be a list of {size} numbers")
    for index, item in enumerate(value):
        _number(item, f"{where}[{index}]")


def _only(data: dict[str, Any], allowed: tuple[str, ...], where: str) -> None:
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise _fail(where, f"unknown field(s) {', '.join(unknown)} (allowed: {', '.join(allowed)})")


def _ids(items: Any, where: str) -> list[dict[str, Any]]:
    if not isinstance(items, list) or len(items) > MAX_ITEMS:
        raise _fail(where, f"must be a list of at most {MAX_ITEMS}")
    seen: set[str] = set()
    for index, item in enumerate(items):
        _mapping(item, f"{where}[{index}]")
        item_id = _text(item.get("id"), f"{where}[{index}].id", 64)
        if item_id in seen:
            raise _fail(f"{where}[{index}].id", f"{item_id!r} is used twice")
        seen.add(item_id)
    return items


def check_object(item: dict[str, Any], where: str) -> None:
    """Raise WorldError unless `item` is an object scene.py can build."""
    if item.get("model") not in MODELS:
        raise _fail(f"{where}.model", f"must be one of {', '.join(MODELS)}")
    _vector(item.get("pose"), f"{where}.pose", 3)
    if item["model"] == "gate":
        _number(item.get("width"), f"{where}.width", 0.1)


def check_terrain(patch: dict[str, Any], where: str) -> None:
    """Raise WorldError unless `patch` is a terrain patch scene.py can build."""
    kind = patch.get("kind")
    if kind not in TERRAIN_FIELDS:
        raise _fail(f"{where}.kind", f"must be one of {', '.join(TERRAIN_FIELDS)}")
    optional = TERRAIN_OPTIONAL[kind]
    _only(patch, ("id", "kind", "min", "max", *TERRAIN_FIELDS[kind], *optional), where)
    _vector(patch.get("min"), f"{where}.min", 2)
    _vector(patch.get("max"), f"{where}.max", 2)
    if any(lo >= hi for lo, hi in zip(patch["min"], patch["max"], strict=True)):
        raise _fail(where, "min must be below max on both axes")
    for name in TERRAIN_FIELDS[kind]:
        _number(patch.get(name), f"{where}.{name}", 0.0)
    for name in (n for n in optional if n in patch):
        _number(patch[name], f"{where}.{name}", 0.0)
    if kind == "rubble" and not (isinstance(patch["blocks"], int) and patch["blocks"] <= 500):
        raise _fail(f"{where}.blocks", "must be a whole number up to 500")


def check_condition(condition: Any, gates: set[str], where: str, depth: int = 0) -> None:
    """Raise WorldError unless `condition` is one the scorer evaluates (see scoring.py)."""
    if depth > MAX_DEPTH:
        raise _fail(where, f"conditions nest at most {MAX_DEPTH} deep")
    if not isinstance(condition, dict) or len(condition) != 1:
        raise _fail(where, "a condition is an object with exactly one key")
    ((kind, arg),) = condition.items()
    inner = f"{where}.{kind}"
    if kind in ("all", "any"):
        if not isinstance(arg, list) or not arg:
            raise _fail(inner, "must be a non-empty list of conditions")
        for index, part in enumerate(arg):
            check_condition(part, gates, f"{inner}[{index}]", depth + 1)
    elif kind in ("flag", "not_flag"):
        _text(arg, inner, 64)
    elif kind in QUANTITY_CONDITIONS:
        _only(_mapping(arg, inner), ("quantity", "value"), inner)
        _text(arg.get("quantity"), f"{inner}.quantity", 64)
        _number(arg.get("value"), f"{inner}.value")
    elif kind == "through_gate":
        _only(_mapping(arg, inner), ("body", "gate"), inner)
        if arg.get("body") not in BODIES:
            raise _fail(f"{inner}.body", f"must be one of {', '.join(BODIES)}")
        if arg.get("gate") not in gates:
            raise _fail(f"{inner}.gate", f"{arg.get('gate')!r} is not a gate of this world")
    else:
        raise _fail(where, f"unknown condition {kind!r}")


def check_top(data: Any) -> dict[str, Any]:
    """Raise WorldError unless the document's shared part (before configurations) is sound."""
    doc = _mapping(data, "world")
    name = doc.get("name")
    if not isinstance(name, str) or not NAME.fullmatch(name):
        raise _fail("name", "must be lower-case letters, digits and _ (at most 64)")
    missing = [key for key in (*TOP_REQUIRED, "checkpoints", "configs") if key not in doc]
    if missing:
        raise _fail(name, f"missing field(s) {', '.join(missing)}")
    _only(doc, TOP_KEYS, name)
    _text(doc["title"], f"{name}.title")
    _number(doc["time_limit_s"], f"{name}.time_limit_s", 1.0)
    _only(_mapping(doc["ground"], f"{name}.ground"), ("friction",), f"{name}.ground")
    _number(doc["ground"].get("friction"), f"{name}.ground.friction", 0.0)
    _only(_mapping(doc["robot"], f"{name}.robot"), ("start",), f"{name}.robot")
    _vector(doc["robot"].get("start"), f"{name}.robot.start", 3)
    for index, item in enumerate(_ids(doc["objects"], f"{name}.objects")):
        check_object(item, f"{name}.objects[{index}]")
    for index, patch in enumerate(_ids(doc["terrain"], f"{name}.terrain")):
        check_terrain(patch, f"{name}.terrain[{index}]")
    gates = {item["id"] for item in doc["objects"] if item["model"] == "gate"}
    checkpoints = doc["checkpoints"]
    if not isinstance(checkpoints, list) or not 0 < len(checkpoints) <= MAX_ITEMS:
        raise _fail(f"{name}.checkpoints", f"must be a list of 1 to {MAX_ITEMS}")
    for index, checkpoint in enumerate(checkpoints):
        where = f"{name}.checkpoints[{index}]"
        _only(_mapping(checkpoint, where), ("name", "when"), where)
        _text(checkpoint.get("name"), f"{where}.name")
        check_condition(checkpoint.get("when"), gates, f"{where}.when")
    for key, value in _mapping(doc.get("assists", {}), f"{name}.assists").items():
        _number(value, f"{name}.assists.{key}", 0.0)
    return doc


def check_config_overrides(name: str, key: str, overrides: Any) -> dict[str, Any]:
    """Raise WorldError unless a run configuration's overrides have the allowed shape."""
    where = f"{name}.configs.{key}"
    if not (key.isascii() and key.isdigit()) or not 1 <= int(key) <= 100:
        raise _fail(where, "run configurations are numbered 1..100")
    data = _mapping(overrides, where)
    _only(data, CONFIG_KEYS, where)
    seed = data.get("seed")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise _fail(f"{where}.seed", f"must be a whole number 0..{MAX_SEED}")
    robot = _mapping(data.get("robot", {}), f"{where}.robot")
    _only(robot, ("start",), f"{where}.robot")
    if "start" in robot:
        _vector(robot["start"], f"{where}.robot.start", 3)
    ground = _mapping(data.get("ground", {}), f"{where}.ground")
    _only(ground, ("friction",), f"{where}.ground")
    if "friction" in ground:
        _number(ground["friction"], f"{where}.ground.friction", 0.0)
    for part in ("objects", "terrain"):
        for item_id, value in _mapping(data.get(part, {}), f"{where}.{part}").items():
            _mapping(value, f"{where}.{part}.{item_id}")
    return data
