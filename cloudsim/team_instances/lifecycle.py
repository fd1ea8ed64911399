"""A team instance's life: the one place its state changes.

deploying -> ready | error; ready <-> unreachable (health checks); any -> terminated.
Its constellation does the deploying; the health poll (`health.poll`) watches both and calls
here.
"""

from __future__ import annotations

from typing import Any

from cloudsim.models import InstanceState, TeamInstance, utcnow


def deploying(instance: TeamInstance) -> None:
    """Mark an instance as being deployed (its constellation launching)."""
    instance.state, instance.error = InstanceState.DEPLOYING, None


def failed(instance: TeamInstance, error: str) -> None:
    """Mark an instance's deployment as failed, with why."""
    instance.state, instance.error = InstanceState.ERROR, error


def healthy(instance: TeamInstance, url: str, health: dict[str, Any]) -> None:
    """Record a health check the instance answered: it is ready (even if a part of it is down,
    which its health shows)."""
    instance.state, instance.error = InstanceState.READY, None
    instance.url = url
    instance.version = str(health.get("version", ""))[:64] or None
    instance.health = health
    instance.checked_at = instance.heard_at = utcnow()


def unreachable(instance: TeamInstance, error: str) -> None:
    """Record a health check the instance did not answer (or answered with the wrong
    certificate)."""
    instance.state, instance.error = InstanceState.UNREACHABLE, error
    instance.checked_at = utcnow()


def terminated(instance: TeamInstance) -> None:
    """Mark an instance as gone with its constellation."""
    instance.state = InstanceState.TERMINATED
