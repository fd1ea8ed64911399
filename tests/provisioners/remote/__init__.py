"""Tests of the remote-configuration toolkit: SSH, operations, PKI."""
