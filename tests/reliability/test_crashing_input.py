"""A file that crashes OCCT's reader ends a forked reading child, not the worker: the job fails at once with
unreadable_cad (one attempt), and the same worker process takes the next job."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import corpus
from tests.service.conftest import submit, wait_status

HEADER = ("ISO-10303-21;\nHEADER;\nFILE_DESCRIPTION(('x'),'2;1');\nFILE_NAME('x','2026-01-01T00:00:00',(''),(''),'',"
          "'','');\nFILE_SCHEMA(('AUTOMOTIVE_DESIGN'));\nENDSEC;\nDATA;\n")
FOOTER = "ENDSEC;\nEND-ISO-10303-21;\n"
#: two STEP files that segfault OCCT's reader: deeply nested parentheses, and an edge loop whose oriented edges
#: refer to each other
CRASHING = {
    "nested": "#1=CARTESIAN_POINT(''," + "(" * 200_000 + "1.0" + ")" * 200_000 + ");\n",
    "cycle": ("#1=SHAPE_REPRESENTATION('',(#2),#3);\n#2=AXIS2_PLACEMENT_3D('',#4,#5,#6);\n"
              "#3=GEOMETRIC_REPRESENTATION_CONTEXT(3);\n#4=CARTESIAN_POINT('',(0.,0.,0.));\n"
              "#5=DIRECTION('',(0.,0.,1.));\n#6=DIRECTION('',(1.,0.,0.));\n"
              "#7=ADVANCED_BREP_SHAPE_REPRESENTATION('',(#8),#3);\n#8=MANIFOLD_SOLID_BREP('',#9);\n"
              "#9=CLOSED_SHELL('',(#10));\n#10=ADVANCED_FACE('',(#11),#12,.T.);\n#11=FACE_OUTER_BOUND('',#13,.T.);\n"
              "#12=PLANE('',#2);\n#13=EDGE_LOOP('',(#14));\n#14=ORIENTED_EDGE('',*,*,#15,.T.);\n"
              "#15=ORIENTED_EDGE('',*,*,#14,.T.);\n"),
}


@pytest.mark.parametrize("name", list(CRASHING))
def test_a_crashing_file_is_unreadable_cad_and_the_worker_lives_on(service, tmp_path: Path, name):
    step = tmp_path / f"{name}.step"
    step.write_text(HEADER + CRASHING[name] + FOOTER)
    with service.client() as c:
        job = submit(c, step, params='{"reuse": false}').json()
        job = wait_status(c, job["id"], ("succeeded", "failed"), 300)
        assert job["status"] == "failed" and job["error"]["code"] == "unreadable_cad", job["error"]
        assert job["attempts"] == 1, "the worker process died on it"
        ok = submit(c, corpus("voron_vhb_din_mount.step"), params='{"reuse": false}').json()
        ok = wait_status(c, ok["id"], ("succeeded", "failed"), 300)
        assert ok["status"] == "succeeded" and ok["worker"] == job["worker"]
