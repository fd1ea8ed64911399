"""drcsim: the bundled DRC simulator (humanoid, vehicle, VRC tasks, scoring, network API)."""

__version__ = "0.1.0"
