"""The real service of tests/service (Redis, Celery workers, the API over HTTP), for the reliability probes."""

from tests.service.conftest import keyed_api, service  # noqa: F401  (fixtures)
