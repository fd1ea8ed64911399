"""Errors raised by the servers provider; every one derives from ServersProviderError."""

from provisioners.providers import errors


class ServersProviderError(errors.ProviderError):
    """Base class of every error the servers provider raises."""


class InventoryError(ServersProviderError):
    """The inventory is malformed; the message names the entry and the field."""


class InvalidRequestError(ServersProviderError):
    """An argument (name, network, auth, size) is not acceptable."""


class NoFreeServerError(ServersProviderError):
    """No free server (or pre-made network) fits the request."""


class NetworkNotFoundError(ServersProviderError):
    """No network of that name is in use."""


class NetworkInUseError(ServersProviderError):
    """A network cannot be released while servers are claimed in it."""


class StateError(ServersProviderError, errors.StateError):
    """The state file under state_dir cannot be read or written."""


class ServerSetupError(ServersProviderError):
    """Preparing a claimed server over SSH failed; the claim stays, marked failed."""


class ServerCleanupError(ServersProviderError):
    """Cleaning a server up failed on every way in; the server stays claimed by its node."""
