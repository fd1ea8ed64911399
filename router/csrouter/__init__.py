"""csrouter: the OCU path of a CloudSim router (delay, accounting, caps, bandwidth log).

Packets between the VPN (tun) and the LAN reach this daemon through iptables NFQUEUE, one
queue per direction. Each packet is measured (IP bytes, TCP/UDP payload bytes), checked
against the armed run's cap for its direction, then either dropped or held for the armed
latency and accepted. The orchestrator drives it with `csrouter arm|counters|status|disarm`
over a root-only Unix socket.
"""

__version__ = "0.1.0"
