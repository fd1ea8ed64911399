"""Constellation fixtures of tests/fleet, for the end-to-end runs."""

from tests.fleet.conftest import fleet_app, fleet_config  # noqa: F401
