"""Errors of the service layer; the web, the API and the CLI each turn them into clear answers."""

from __future__ import annotations


class CloudSimError(Exception):
    """Base of every error CloudSim reports to a person; its message is safe to show."""

    status = 400


class InvalidInput(CloudSimError):
    """The request names something malformed or not allowed."""

    status = 400


class Forbidden(CloudSimError):
    """The actor may not do this."""

    status = 403


class NotFound(CloudSimError):
    """The thing does not exist, or the actor may not know that it does."""

    status = 404

    @classmethod
    def of(cls, kind: str, ref: object) -> NotFound:
        """Return the one answer for a thing that is missing or not the actor's to know about."""
        return cls(f"{kind} {ref} not found")


class Conflict(CloudSimError):
    """The request clashes with the current state (a duplicate name, a busy constellation)."""

    status = 409


class Unavailable(CloudSimError):
    """A service CloudSim depends on (the job queue, a cloud) cannot be reached."""

    status = 503
