"""The `phases:` part of the season YAML, read with a clear error per bad field and written back.

phases:
  - name: qualification
    start: 2026-06-10 09:00          # in the document's time_zone unless the phase has its own
    stop: 2026-06-12 18:00
    worlds:
      - {world: vrc_task_1, configs: [1, 2]}
    entry: {after: practice, min_score: 4}   # or: all (the default)
    limits: {per_task: 2, per_day: 3, total: 6, at_once: 1}   # each optional
    scores: hidden                   # or: live (the default)
    ranking: false                   # its runs count in the overall ranking (default true)
    timeout_s: 1800                  # and latency_ms, uplink_bits, downlink_bits, as tasks
"""

from __future__ import annotations

from typing import Any

from cloudsim.competition.schedule import in_zone, to_utc
from cloudsim.errors import InvalidInput
from cloudsim.models import Phase
from cloudsim.seasons.service import LIMITS, PhaseSpec, check_phase

MAX_PHASES = 50
PHASE_KEYS = {
    "name",
    "start",
    "stop",
    "time_zone",
    "worlds",
    "entry",
    "limits",
    "scores",
    "ranking",
    "timeout_s",
    "latency_ms",
    "uplink_bits",
    "downlink_bits",
}
LIMIT_KEYS = {key.removeprefix("max_runs_"): key for key in LIMITS}


def parse_phases(items: Any, zone_name: str) -> list[PhaseSpec]:
    """Read the document's phases list, naming the phase and field of the first problem."""
    if not isinstance(items, list):
        raise InvalidInput("phases must be a list")
    if len(items) > MAX_PHASES:
        raise InvalidInput(f"a season holds at most {MAX_PHASES} phases")
    specs = []
    for number, item in enumerate(items, start=1):
        label = f"phase {number}"
        if isinstance(item, dict) and isinstance(item.get("name"), str):
            label += f" ({item['name']})"
        try:
            specs.append(check_phase(_phase(item, zone_name, number)))
        except InvalidInput as exc:
            raise InvalidInput(f"{label}: {exc}") from None
    names = [spec.name for spec in specs]
    for number, spec in enumerate(specs, start=1):
        if names.count(spec.name) > 1:
            raise InvalidInput(f"phase {number} ({spec.name}): name: used by two phases")
        if spec.entry_after is not None and spec.entry_after not in names[: number - 1]:
            raise InvalidInput(
                f"phase {number} ({spec.name}): entry: after must name an earlier phase "
                f"of this document, not {spec.entry_after!r}"
            )
    return specs


def _phase(item: Any, zone_name: str, number: int) -> PhaseSpec:
    if not isinstance(item, dict):
        raise InvalidInput("each phase must be a mapping")
    unknown = set(item) - PHASE_KEYS
    if unknown:
        raise InvalidInput(f"unknown keys {', '.join(sorted(map(str, unknown)))}")
    missing = [k for k in ("name", "start", "stop", "worlds") if k not in item]
    if missing:
        raise InvalidInput(f"missing {', '.join(missing)}")
    if not isinstance(item["name"], str):
        raise InvalidInput("name: must be text")
    phase_zone = _text(item.get("time_zone", zone_name), "time_zone")
    times = {}
    for key in ("start", "stop"):
        try:
            times[key] = to_utc(_text(item[key], key), phase_zone)
        except InvalidInput as exc:
            raise InvalidInput(f"{key}: {exc}") from None
    after, min_score = _entry(item.get("entry", "all"))
    numbers = {
        key: _whole(item[key], key)
        for key in ("timeout_s", "latency_ms", "uplink_bits", "downlink_bits")
        if key in item
    }
    return PhaseSpec(
        name=item["name"],
        window_start=times["start"],
        window_stop=times["stop"],
        worlds=_worlds(item["worlds"]),
        time_zone=phase_zone,
        position=number,
        entry_after=after,
        entry_min_score=min_score,
        limits=_limits(item.get("limits", {})),
        scores_hidden=_choice(item.get("scores", "live"), "scores", ("live", "hidden")) == "hidden",
        counts_in_ranking=_flag(item.get("ranking", True), "ranking"),
        **numbers,
    )


def _text(value: Any, name: str) -> str:
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        raise InvalidInput(f"{name}: must be text")
    return str(value)


def _whole(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise InvalidInput(f"{name}: must be a whole number, got {value!r}")
    return value


def _flag(value: Any, name: str) -> bool:
    if not isinstance(value, bool):
        raise InvalidInput(f"{name}: must be true or false, got {value!r}")
    return value


def _choice(value: Any, name: str, allowed: tuple[str, ...]) -> str:
    if value not in allowed:
        raise InvalidInput(f"{name}: must be {' or '.join(allowed)}, got {value!r}")
    return str(value)


def _worlds(value: Any) -> tuple[tuple[str, int], ...]:
    if not isinstance(value, list) or not value:
        raise InvalidInput("worlds: must be a list of {world: NAME, configs: [N, ...]}")
    pairs = []
    for entry in value:
        if not isinstance(entry, dict) or set(entry) != {"world", "configs"}:
            raise InvalidInput("worlds: each entry is {world: NAME, configs: [N, ...]}")
        world = _text(entry["world"], "worlds: world")
        configs = entry["configs"]
        if not isinstance(configs, list) or not configs:
            raise InvalidInput(f"worlds: configs of {world} must be a list of numbers")
        pairs += [(world, _whole(config, f"worlds: a config of {world}")) for config in configs]
    return tuple(pairs)


def _entry(value: Any) -> tuple[str | None, int | None]:
    if value == "all":
        return None, None
    if not isinstance(value, dict) or set(value) != {"after", "min_score"}:
        raise InvalidInput("entry: must be 'all' or {after: PHASE, min_score: N}")
    return _text(value["after"], "entry: after"), _whole(value["min_score"], "entry: min_score")


def _limits(value: Any) -> dict[str, int | None]:
    if not isinstance(value, dict):
        raise InvalidInput(f"limits: must be a mapping of {', '.join(LIMIT_KEYS)}")
    unknown = set(value) - set(LIMIT_KEYS)
    if unknown:
        raise InvalidInput(
            f"limits: unknown {', '.join(sorted(map(str, unknown)))}; "
            f"known: {', '.join(LIMIT_KEYS)}"
        )
    return {LIMIT_KEYS[k]: _whole(v, f"limits: {k}") for k, v in value.items()}


def phase_entries(phases: list[Phase], document_zone: str) -> list[dict[str, Any]]:
    """Write the phases as the document's `phases:` list (what parse_phases reads back)."""
    return [_entry_of(phase, document_zone) for phase in phases]


def _entry_of(phase: Phase, document_zone: str) -> dict[str, Any]:
    worlds: dict[str, list[int]] = {}
    for world, config in phase.worlds:
        worlds.setdefault(world, []).append(config)
    entry: dict[str, Any] = {
        "name": phase.name,
        "start": _wall_clock(phase, "window_start"),
        "stop": _wall_clock(phase, "window_stop"),
    }
    if phase.time_zone != document_zone:
        entry["time_zone"] = phase.time_zone
    entry["worlds"] = [{"world": w, "configs": c} for w, c in worlds.items()]
    entry["entry"] = (
        "all"
        if phase.entry_phase is None
        else {"after": phase.entry_phase.name, "min_score": phase.entry_min_score}
    )
    limits = {name: getattr(phase, key) for name, key in LIMIT_KEYS.items()}
    entry["limits"] = {name: value for name, value in limits.items() if value is not None}
    entry["scores"] = "hidden" if phase.scores_hidden else "live"
    entry["ranking"] = phase.counts_in_ranking
    for key in ("timeout_s", "latency_ms", "uplink_bits", "downlink_bits"):
        entry[key] = getattr(phase, key)
    return entry


def _wall_clock(phase: Phase, column: str) -> str:
    local = in_zone(getattr(phase, column), phase.time_zone)
    return local.strftime("%Y-%m-%d %H:%M" + (":%S" if local.second else ""))
