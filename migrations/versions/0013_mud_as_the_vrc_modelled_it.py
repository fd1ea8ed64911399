"""worlds: mud as the VRC modelled it (depth, drag, bottom friction) in stored world documents

Revision ID: 0013
Revises: 0012
Create Date: 2026-11-23 09:40:00
"""

from __future__ import annotations

import copy
from typing import Any

from drcsim.worlds import WORLD_NAMES, shipped_document

from migrations.stored_worlds import rewrite

revision = "0013"
down_revision = "0012"
branch_labels = None
depends_on = None

MUD_FIELDS = ("friction", "depth", "damping")
# For a mud patch the shipped world does not have: config 1's mud of vrc_task_2.
DEFAULT_MUD = {"friction": 1.0, "depth": 0.08, "damping": 150.0}

def _mud_fields(patch: dict[str, Any] | None) -> dict[str, Any]:
    return {k: patch[k] for k in MUD_FIELDS if patch and k in patch}


def migrated(document: dict[str, Any], shipped: dict[str, Any] | None) -> dict[str, Any] | None:
    """Return `document` with its old soft-slab mud (stiffness, no depth) replaced by the
    shipped world's mud, patch by patch and configuration by configuration; None if it has none."""
    new = copy.deepcopy(document)
    shipped_base = {p["id"]: p for p in (shipped or {}).get("terrain", [])}
    shipped_configs = (shipped or {}).get("configs", {})
    changed = False
    for patch in new.get("terrain", []):
        if patch.get("kind") != "mud" or "depth" in patch:
            continue
        changed = True
        patch.pop("stiffness", None)
        patch.update(_mud_fields(shipped_base.get(patch["id"])) or DEFAULT_MUD)
        for key, config in new.get("configs", {}).items():
            override = config.get("terrain", {}).get(patch["id"])
            if override is None:
                continue
            for field in ("stiffness", *MUD_FIELDS):
                override.pop(field, None)
            shipped_override = shipped_configs.get(key, {}).get("terrain", {}).get(patch["id"])
            override.update(_mud_fields(shipped_override))
    return new if changed else None


def upgrade() -> None:
    # Stored documents made before drcsim modelled mud as the VRC did no longer load (their
    # mud has `stiffness` and no `depth`): they take the shipped worlds' mud, a new version.
    rewrite(lambda name, doc: migrated(doc, shipped_document(name) if name in WORLD_NAMES else None))


def downgrade() -> None:
    # The old mud's fields are not restored: a document with them no longer loads anyway.
    pass
