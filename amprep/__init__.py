"""amprep: additive-manufacturing pre-processing (CAD → closed STL/3MF within tolerance, with an error report)."""

import os
from importlib.metadata import PackageNotFoundError, version

# numpy's OpenBLAS starts a thread per core at import that spins on sched_yield while it waits for work: on two cores
# that slowed OCCT's (single-threaded) STEP reader by 12-15 % (a 4,806-face part: 8.5 s → 10.1 s). amprep's linear
# algebra is on 3 × 3 blocks, where threads do not help; set before numpy is imported anywhere (a value given wins)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

try:
    __version__ = version("amprep")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0"
