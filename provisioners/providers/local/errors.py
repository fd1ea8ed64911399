"""Errors raised by the local provider; every one derives from LocalProviderError."""

from provisioners.providers.errors import ProviderError


class LocalProviderError(ProviderError):
    """Base class of every error the local provider raises."""


class NotRootError(LocalProviderError):
    """The provider was used by a process that is not root."""


class InvalidRequestError(LocalProviderError):
    """An argument (name, address, size, auth, init mode) is not acceptable."""


class NameInUseError(LocalProviderError):
    """A network or node with that name already exists under this prefix."""


class NetworkNotFoundError(LocalProviderError):
    """No network with that name exists under this prefix."""


class NetworkInUseError(LocalProviderError):
    """A network cannot be destroyed while nodes are attached to it."""


class AddressError(LocalProviderError):
    """An address or subnet clashes with one in use, or a pool is exhausted."""


class CommandError(LocalProviderError):
    """A system command (ip, mount, ...) failed."""


class HostBootError(LocalProviderError):
    """A host did not come up (its sshd never accepted a connection)."""


class HostStopError(LocalProviderError):
    """A host's processes did not go away after SIGKILL."""
