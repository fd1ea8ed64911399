"""Background jobs: the Celery queue, the job runner, and the pages that follow jobs."""
