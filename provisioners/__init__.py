"""Where machines come from and how they are configured, in two halves.

- `providers/`: the providers as libcloud NodeDrivers behind one declared interface
  (`providers.base.CloudSimNodeDriver`), their registry and settings checks, the state they
  keep on this controller; the drivers in `providers/local`, `providers/ec2`,
  `providers/servers`.
- `remote/`: the remote-configuration toolkit, provider-agnostic: the SSH executor
  (`remote/ssh`), facts read from a machine (`remote/facts`), idempotent operations that
  close the difference (`remote/operations`), firewall rules (`remote/firewall.py`) and the
  team VPN's certificates (`remote/pki.py`).
"""
