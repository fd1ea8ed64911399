"""The providers' exception hierarchy: every provider's errors derive from ProviderError."""

from __future__ import annotations


class ProviderError(Exception):
    """Base class of every error a provider raises."""


class SettingsError(ProviderError, ValueError):
    """A provider's settings are missing or malformed; the message says which."""


class StateError(ProviderError):
    """A provider's state on this controller cannot be read or written."""
