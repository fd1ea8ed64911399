"""Tests of the providers (local, ec2, servers) and their shared parts."""
