"""Teams and users: management by officers and admins."""
