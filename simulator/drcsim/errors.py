"""The one exception hierarchy of the simulator layer."""


class DrcsimError(Exception):
    """Base class of every error the simulator raises on purpose."""


class WorldError(DrcsimError):
    """A world or run configuration is unknown or malformed."""


class CommandError(DrcsimError):
    """A command is malformed or cannot be applied in the current state."""


class ProtocolError(DrcsimError):
    """A network message is malformed, oversized or not allowed."""

    request_id: int | None = None  # the refused message's id, when it had a readable one


class ClientError(DrcsimError):
    """The client library could not talk to the server."""


class ReplayMismatch(DrcsimError):
    """A replayed run diverged from the recorded one."""
