"""Limits the library and the job definitions share (the API may import this module: it loads nothing)."""

#: the finest chord tolerance (mm): a tenth of a micron, under what binary STL's float32 resolves on a 400 mm part
MIN_TOLERANCE = 1e-4
