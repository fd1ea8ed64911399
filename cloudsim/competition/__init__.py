"""The competition: tasks scheduled by officers, runs made by teams, their logs and scores."""
