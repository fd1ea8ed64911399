"""A Celery app for a worker started as a separate process by tests (it knows the test jobs)."""

from cloudsim.app import create_app
from tests.support import job_kinds  # noqa: F401  (registers the test job kinds)

flask_app = create_app()
celery_app = flask_app.extensions["celery"]
