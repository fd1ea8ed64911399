"""Declarative definitions of constellation kinds: machines, network, firewall, deploy plans."""
