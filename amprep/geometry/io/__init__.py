"""Files out: STL, 3MF, writing by extension, and the report's PNG plots."""
