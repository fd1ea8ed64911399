"""libcloud's EC2 connection and response, made to work with moto and to raise our errors."""

from collections.abc import Iterable
from typing import Any, NoReturn

import requests
from libcloud.common.types import LibcloudError, MalformedResponseError
from libcloud.compute.drivers.ec2 import NAMESPACE, EC2Connection, EC2Response
from libcloud.utils.xml import findall_ignore_namespace, findtext_ignore_namespace

from provisioners.providers.ec2.errors import (
    EC2APIError,
    EC2ConnectionError,
    EC2CredentialsError,
    EC2ProviderError,
)

# AWS answers with namespace ".../2016-11-15/"; moto drops the trailing slash.
_MOTO_NAMESPACE_ATTRIBUTE = f'xmlns="{NAMESPACE.rstrip("/")}"'
_AWS_NAMESPACE_ATTRIBUTE = f'xmlns="{NAMESPACE}"'

CREDENTIALS_ERROR_CODES = frozenset(
    {
        "AuthFailure",
        "InvalidClientTokenId",
        "SignatureDoesNotMatch",
        "OptInRequired",
        "UnauthorizedOperation",
        "MissingAuthenticationToken",
        "InvalidAccessKeyId",
    }
)
_MESSAGE_LIMIT = 500
_REDACTED = "[redacted]"


def scrub(text: str, secrets: Iterable[str | None]) -> str:
    """Return text with every occurrence of each non-empty secret replaced by a marker."""
    for secret in secrets:
        if secret:
            text = text.replace(secret, _REDACTED)
    return text


class CloudSimEC2Response(EC2Response):  # type: ignore[misc]
    """An EC2 response that parses moto's XML and turns EC2 errors into EC2APIError."""

    def parse_body(self) -> Any:
        """Parse the XML body, accepting moto's namespace spelling as well as AWS's."""
        # Harmless against AWS: its namespace already has the slash, so nothing matches.
        self.body = str(self.body or "").replace(
            _MOTO_NAMESPACE_ATTRIBUTE, _AWS_NAMESPACE_ATTRIBUTE, 1
        )
        return super().parse_body()

    def parse_error(self) -> NoReturn:
        """Raise EC2APIError (EC2CredentialsError for auth codes) with AWS's code and message."""
        secrets = _connection_secrets(self.connection)
        fallback_code = f"HTTP{self.status}"
        fallback_class = EC2CredentialsError if self.status in (401, 403) else EC2APIError
        try:
            root = self.parse_body()
        except MalformedResponseError:
            root = None  # not XML: a proxy's page or a load balancer's 503
        # AWS's <Response><Errors><Error> has no namespace; moto's has one.
        errors = (
            []
            if root is None or isinstance(root, str)
            else (findall_ignore_namespace(root, "Errors/Error", NAMESPACE))
        )
        if not errors:
            body = scrub(str(self.body or "")[:_MESSAGE_LIMIT], secrets) or "(empty body)"
            raise fallback_class(fallback_code, body, self.status) from None
        code = findtext_ignore_namespace(errors[0], "Code", NAMESPACE) or fallback_code
        message = scrub(findtext_ignore_namespace(errors[0], "Message", NAMESPACE) or "", secrets)
        error_class = EC2CredentialsError if code in CREDENTIALS_ERROR_CODES else EC2APIError
        raise error_class(code, message[:_MESSAGE_LIMIT], self.status)


class CloudSimEC2Connection(EC2Connection):  # type: ignore[misc]
    """An EC2 connection whose every failure is an EC2ProviderError free of credentials."""

    responseCls = CloudSimEC2Response

    def request(self, *args: Any, **kwargs: Any) -> Any:
        """Send a signed EC2 request; raise EC2ProviderError subclasses on any failure."""
        try:
            return super().request(*args, **kwargs)
        except EC2ProviderError:
            raise
        except (requests.RequestException, OSError) as error:
            # "from None": transport errors carry the signed URL and headers.
            raise EC2ConnectionError(
                f"cannot reach EC2 at {self.host}:{self.port}: {type(error).__name__}: "
                f"{scrub(str(error), _connection_secrets(self))[:_MESSAGE_LIMIT]}"
            ) from None
        except LibcloudError as error:
            raise EC2ConnectionError(
                f"EC2 at {self.host}:{self.port} answered unexpectedly: "
                f"{scrub(str(error), _connection_secrets(self))[:_MESSAGE_LIMIT]}"
            ) from None


def _connection_secrets(connection: Any) -> list[str | None]:
    # SignedAWSConnection keeps the access key id as user_id and the secret as key.
    return [
        getattr(connection, "key", None),
        getattr(connection, "user_id", None),
        getattr(connection, "token", None),
    ]
