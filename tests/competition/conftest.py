"""Constellation fixtures of tests/launched_constellations, for the end-to-end runs."""

from tests.launched_constellations.conftest import constellations_app, constellations_config  # noqa: F401
