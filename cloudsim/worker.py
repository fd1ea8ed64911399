"""Entry point of the Celery worker and beat: `celery -A cloudsim.worker worker`."""

from cloudsim.app import create_app

flask_app = create_app()
celery_app = flask_app.extensions["celery"]
