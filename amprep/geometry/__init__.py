"""The pure geometry library (no web, queue or validation framework): arrays and OCCT shapes in, meshes, reports
and plots out. Its wings, lowest first: core · parallel → cad → measure → io → meshing → refine · placement."""
