"""The EC2 provider: libcloud's EC2 driver extended with CloudSim's network and firewall calls."""
