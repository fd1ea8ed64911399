"""The landing page, one per role."""
