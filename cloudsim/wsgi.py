"""Entry point of the WSGI server: `gunicorn cloudsim.wsgi:app`."""

from cloudsim.app import create_app

app = create_app()
