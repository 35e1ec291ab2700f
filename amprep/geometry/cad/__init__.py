"""CAD in: reading STEP/IGES/BREP in millimetres, sewing, wire checks, the B-rep topology and exact surfaces S(u,v)."""
