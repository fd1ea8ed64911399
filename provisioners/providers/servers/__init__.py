"""The `servers` provider: machines that already exist, as an apache-libcloud NodeDriver.

An inventory lists the servers (address, SSH login, LAN and its CIDR). Networks are the
inventory's pre-made LANs: ex_create_network hands out one whose servers are all free.
create_node claims a free server of that LAN and, over SSH with the inventory's key, sets
its hostname to the node's name and installs the node's public key; destroy_node removes
what CloudSim put there (keys, services, CLOUDSIM-* chains, its files), puts back the
server's /etc/hosts, /etc/motd, default route, firewall and ip_forward, its own hostname, and
frees it. A server that cannot be cleaned up is freed anyway (terminate must finish) with a
warning in the state, and is cleaned before its next claim. Claims live in a JSON file under
state_dir, so any later driver rediscovers them. See README.md. Modules: driver (the
libcloud API), inventory, claims (choosing servers), remote (the SSH work), state,
nodes (libcloud objects from claims); host keys are pinned in the inventory or recorded in
the state.
"""
