"""CAD → closed mesh within the chord tolerance: pipeline.py is the entry point, tolerance.py and enforce.py where
the tolerance is worked out and kept."""
