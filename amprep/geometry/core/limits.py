"""Limits the library and the job definitions share (the API may import this module: it loads nothing)."""

#: the finest chord tolerance (mm): a tenth of a micron, under what binary STL's float32 resolves on a 400 mm part
MIN_TOLERANCE = 1e-4
#: the coarsest (mm; an int, as the published OpenAPI schema writes it)
MAX_TOLERANCE = 100

#: the triangles a job may output unless told otherwise (a 500 MB binary STL); the service caps it (AMPREP_MAX_TRIANGLES)
DEFAULT_MAX_TRIANGLES = 10_000_000
#: the most a job may ask for
MAX_TRIANGLES_CAP = 50_000_000
