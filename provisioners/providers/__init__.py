"""Providers: where machines come from, as libcloud NodeDrivers with one declared interface.

`base` declares the driver every provider implements (libcloud's NodeDriver plus CloudSim's
network extensions, with defaults), `registry` lists the providers with their settings
checks, `state` is the one JSON state store drivers keep on this controller, `errors` the
exception hierarchy. The drivers themselves live in `local/`, `ec2/` and `servers/`.
"""
