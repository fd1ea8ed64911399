"""Constellation kinds: the shipped ones load; a bad definition is refused naming the field."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml

from constellations.definition import (
    KINDS_DIR,
    DefinitionError,
    available_kinds,
    load_kind,
    parse_kind,
)
from constellations.plans import PLANS

VRC = yaml.safe_load((KINDS_DIR / "vrc.yaml").read_text())


def test_shipped_kinds_load_with_known_plans() -> None:
    assert available_kinds() == ["cloudsim", "simple", "vrc"]
    vrc = load_kind("vrc", set(PLANS))
    assert [m.name for m in vrc.machines] == ["router", "sim", "fc1", "fc2"]
    assert [m.name for m in vrc.machines if m.public] == ["router"]
    assert vrc.machine("sim").address("10.211.7.0/24") == "10.211.7.51"
    assert vrc.roles == ["router", "sim", "fc"]
    denied = {(c.source, c.target) for c in vrc.reachability if not c.allowed}
    assert ("public", "sim") in denied


def _with(change: dict[str, Any]) -> dict[str, Any]:
    data = copy.deepcopy(VRC)
    for path, value in change.items():
        target = data
        keys = path.split(".")
        for key in keys[:-1]:
            target = target[int(key)] if key.isdigit() else target[key]
        last = keys[-1]
        target[int(last) if last.isdigit() else last] = value
    return data


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"name": "Bad Name"}, "name must be lowercase"),
        ({"machines": []}, "vrc.machines must list at least one machine"),
        ({"machines.1.host": 300}, "vrc.machines[1].host must be between 2 and 254"),
        ({"machines.1.host": "51"}, "vrc.machines[1].host must be a int"),
        ({"machines.2.name": "sim"}, "machine names must be unique"),
        ({"machines.3.host": 52}, "two machines have the same host number"),
        (
            {"machines.0.plan": ["common", "teleport"]},
            "vrc.machines[0].plan: unknown deploy plan 'teleport'",
        ),
        ({"machines.0.role": "Router!"}, "vrc.machines[0].role must be a role name"),
        ({"network.gateway": "nowhere"}, "vrc.network.gateway: no machine named 'nowhere'"),
        ({"network.prefix": 8}, "vrc.network.prefix must be between 16 and 28"),
        ({"firewall.0.protocol": "smtp"}, "vrc.firewall[0]: protocol must be one of"),
        ({"firewall.0.ports": [90, 80]}, "vrc.firewall[0]: ports must satisfy"),
        ({"firewall.0.to": "gpu"}, "vrc.firewall[0]: no machine has role 'gpu'"),
        ({"firewall.1.from": "ocu"}, "vrc.firewall[1]: no machine has role 'ocu'"),
        (
            {"reachability.allow.0": ["router", "moon", 22]},
            "vrc.reachability.allow[0]: unknown machine 'moon'",
        ),
        (
            {"reachability.deny.0": ["public", "sim"]},
            "vrc.reachability.deny[0] must be [source, target, port]",
        ),
    ],
)
def test_bad_definitions_name_the_field(change: dict[str, Any], message: str) -> None:
    with pytest.raises(DefinitionError) as error:
        parse_kind(_with(change), set(PLANS))
    assert message in str(error.value)


def test_unknown_kind_lists_the_known_ones(tmp_path: Path) -> None:
    with pytest.raises(
        DefinitionError,
        match=r"unknown constellation kind 'moon' \(known: "
        r"cloudsim, simple, vrc\)",
    ):
        load_kind("moon")
    (tmp_path / "odd.yaml").write_text("name: other\nmachines: [{name: a, host: 2, plan: []}]\n")
    with pytest.raises(DefinitionError, match=r"odd\.yaml: name must be 'odd', got 'other'"):
        load_kind("odd", directory=tmp_path)
