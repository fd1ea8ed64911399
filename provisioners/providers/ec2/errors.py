"""Errors raised by the EC2 provider; every one derives from EC2ProviderError."""

from provisioners.providers.errors import ProviderError


class EC2ProviderError(ProviderError):
    """Base class of every error the EC2 provider raises."""


class InvalidRequestError(EC2ProviderError):
    """An argument (name, CIDR, address, auth, role, rule) is not acceptable."""


class EC2APIError(EC2ProviderError):
    """EC2 refused a request; code and message are AWS's own."""

    def __init__(self, code: str, message: str, status: int | None = None) -> None:
        super().__init__(f"EC2 error {code}: {message}")
        self.code = code
        self.message = message
        self.status = status


class EC2CredentialsError(EC2APIError):
    """The credentials are missing, unknown to AWS or not allowed to act."""


class EC2ConnectionError(EC2ProviderError):
    """The EC2 endpoint could not be reached or answered something that is not EC2 XML."""


class NameInUseError(EC2ProviderError):
    """A network or node of that name exists with different settings."""


class NetworkNotFoundError(EC2ProviderError):
    """No network with that name exists."""


class NetworkInUseError(EC2ProviderError):
    """A network cannot be destroyed while instances are in it."""


class EC2TimeoutError(EC2ProviderError):
    """A resource did not reach the awaited state before the deadline."""
