"""Measures of a mesh: chordal error, cusp height, cylindricity, regularity, defects, and the report they make."""
