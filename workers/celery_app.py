"""The worker's Celery app: `celery -A workers.celery_app worker -Q quick,heavy,callbacks`."""

from __future__ import annotations

from celery import signals

from amprep.logs import setup_logging
from amprep.queue import make_celery

app = make_celery()
app.conf.include = ["workers.tasks"]


@signals.setup_logging.connect
def _json_logs(**_: object) -> None:
    setup_logging()


@signals.worker_init.connect
def _preload(**_: object) -> None:
    """Import OCCT and the geometry library once in the parent, so each fresh child process starts warm.

    Imports only: meshing here could start OCCT's thread pool, which a forked child would inherit broken.
    """
    import importlib

    for name in ("amprep.jobs.runner", "amprep.jobs.convert", "amprep.jobs.analyze", "amprep.jobs.refine",
                 "amprep.geometry.meshing.face_mesher", "manifold3d", "lib3mf", "triangle", "scipy.sparse.csgraph"):
        importlib.import_module(name)
    from amprep.geometry.measure.chordal import load_kernels

    load_kernels()  # numba and the compiled kernels: a long-lived worker uses them for every job
