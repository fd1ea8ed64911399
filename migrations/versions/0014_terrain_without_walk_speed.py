"""worlds: terrain patches without `walk_speed` (it scaled the balance harness's walk, now gone)

Revision ID: 0014
Revises: 0013
Create Date: 2026-11-23 10:00:00
"""

from __future__ import annotations

import copy
from typing import Any

from migrations.stored_worlds import rewrite

revision = "0014"
down_revision = "0013"
branch_labels = None
depends_on = None

def migrated(document: dict[str, Any]) -> dict[str, Any] | None:
    """Return `document` without `walk_speed` in its terrain and overrides; None if it had none."""
    new = copy.deepcopy(document)
    patches = list(new.get("terrain", []))
    for config in new.get("configs", {}).values():
        patches += list(config.get("terrain", {}).values())
    changed = False
    for patch in patches:
        if isinstance(patch, dict) and "walk_speed" in patch:
            del patch["walk_speed"]
            changed = True
    return new if changed else None


def upgrade() -> None:
    # The walker walks at the speed its gait and the ground give it: a stored world's
    # `walk_speed` means nothing any more, so it goes (a new version of the document).
    rewrite(lambda _name, document: migrated(document))


def downgrade() -> None:
    # `walk_speed` is not restored: nothing reads it.
    pass
