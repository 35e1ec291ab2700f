"""Work beside this process: one function in a forked child, faces meshed by a pool of forked children."""
