"""Helpers for the test harness: private servers, network ports, waiting."""
