"""Celery workers: the app (celery_app) and one thin task per job kind (tasks)."""
