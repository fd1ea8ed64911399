"""Constellations: launching, verifying and terminating sets of machines, and their pages."""
