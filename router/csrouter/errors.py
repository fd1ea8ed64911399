"""The one exception hierarchy of csrouter."""


class RouterError(Exception):
    """Anything csrouter refuses or fails to do."""


class ConfigError(RouterError):
    """The configuration file or a command's arguments are invalid."""


class DaemonUnavailable(RouterError):
    """The daemon does not answer on its control socket (not running, or wedged)."""


class ControlError(RouterError):
    """The daemon answered a control request with an error."""


class RulesError(RouterError):
    """The NFQUEUE iptables rules could not be read or installed."""
