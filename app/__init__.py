"""The FastAPI front end: routes, the API contract (models) and problem+json errors. Enqueues by task name."""
