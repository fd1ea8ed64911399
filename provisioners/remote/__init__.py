"""The remote-configuration toolkit: SSH, facts, idempotent operations, firewall rules, PKI.

Nothing here knows where a machine came from: it is given an SSH target (`ssh.SSHTarget`).
"""
