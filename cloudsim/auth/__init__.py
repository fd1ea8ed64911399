"""Logging in and out, roles, API tokens."""
