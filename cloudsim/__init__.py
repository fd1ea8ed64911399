"""CloudSim: cloud-hosted, real-time robot simulation competitions."""
