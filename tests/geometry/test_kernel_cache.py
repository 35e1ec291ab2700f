"""`amprep warm` fills numba's cache (the image runs it at build time, docker/Dockerfile): a fresh process then
loads every kernel a real job dispatches instead of compiling it (~20 s on this machine)."""

import json
import os
import subprocess
import sys

from tests.conftest import corpus

# a fresh process on one core (faces meshed in it, not in forked children whose dispatches it cannot see), every
# call large enough for the kernels: the quality mesher's flips and smoothing on the hull's B-splines, the default
# mesher's chordal error, the projections of both, and a Butterfly level; then each kernel's cache hits and misses
_JOB = """
import json, os, sys
os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})
import numba
from amprep.geometry.measure import angles, chordal
from amprep.geometry.cad.read import read_cad
from amprep.geometry.meshing.params import MeshParams
from amprep.geometry.meshing.pipeline import mesh_model
from amprep.geometry.refine.butterfly import ButterflyParams, butterfly_refine
chordal.COMPILED_MIN_POINTS = 0
angles.COMPILED_MIN_TRIANGLES = 0
model = read_cad(sys.argv[1])
r = mesh_model(model, MeshParams(tolerance=0.34, mesher="quality"))
mesh_model(model, MeshParams(tolerance=0.34))
butterfly_refine(r.mesh, ButterflyParams(levels=1))
from amprep.geometry.cad import _bspline_kernel, _projection_kernel
from amprep.geometry.measure import _angle_kernel, _chordal_kernel
from amprep.geometry.refine import _ring_kernel
stats = {}
for mod in (_bspline_kernel, _projection_kernel, _chordal_kernel, _angle_kernel, _ring_kernel):
    for name, fn in vars(mod).items():
        if isinstance(fn, numba.core.registry.CPUDispatcher) and fn.signatures:
            stats[mod.__name__ + "." + name] = (sum(fn.stats.cache_hits.values()), sum(fn.stats.cache_misses.values()))
print(json.dumps(stats))
"""


def test_a_fresh_process_after_amprep_warm_compiles_no_kernel(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path)}
    warm = subprocess.run([sys.executable, "-m", "amprep", "warm"], env=env, capture_output=True, text=True,
                          timeout=900)
    assert warm.returncode == 0, warm.stderr
    assert f"cached in {tmp_path}" in warm.stdout and list(tmp_path.rglob("*.nbi"))
    job = subprocess.run([sys.executable, "-c", _JOB, str(corpus("dtmb5415_bow_hull.iges"))], env=env,
                         capture_output=True, text=True, timeout=900)
    assert job.returncode == 0, job.stderr
    stats = json.loads(job.stdout.strip().splitlines()[-1])
    dispatched = {name.rsplit(".", 2)[-2] for name in stats}
    assert dispatched == {"_bspline_kernel", "_projection_kernel", "_chordal_kernel", "_angle_kernel", "_ring_kernel"}, stats
    assert all(hits > 0 and misses == 0 for hits, misses in stats.values()), json.dumps(stats, indent=0)
