"""Refinement of a tessellation against its CAD: SMA and VTA (thesis 003), adaptive bisection, and the comparison."""
