"""Processes CloudSim starts and supervises on this machine (Redis, workers, web server)."""
