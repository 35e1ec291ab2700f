"""One definition of every job parameter (amprep/jobs/params.py): the API's models, the CLI's options, the runner's
checks, the client and docs/params.md agree with it, default for default and bound for bound."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import pytest
from pydantic import ValidationError

from amprep.cli import build_parser
from amprep.client import main_artifact
from amprep.errors import AmprepError
from amprep.jobs import reference
from amprep.jobs.params import KINDS, Param, build, check, parse_cli_value
from app.models import PARAMS_MODEL

ROOT = Path(__file__).resolve().parents[1]


def _cli_actions(kind: str) -> dict[str, argparse.Action]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return {s: a for a in sub.choices[kind]._actions for s in a.option_strings}


def _outside(p: Param) -> list[float]:
    """Values just past each bound: an excluded bound itself, one step beyond an included one."""
    step = 1 if p.type == "int" else 1e-9
    return ([p.gt] if p.gt is not None else []) + ([p.lt] if p.lt is not None else []) + \
        ([p.ge - step] if p.ge is not None else []) + ([p.le + step] if p.le is not None else [])


@pytest.mark.parametrize("kind", list(KINDS))
def test_every_api_key_is_a_cli_option_with_the_same_default(kind):
    actions = _cli_actions(kind)
    defaults = PARAMS_MODEL[kind]().model_dump(mode="json")
    checked = check(kind, {}, service=True)
    assert set(defaults) == set(checked) == {p.name for p in KINDS[kind].params}
    for p in KINDS[kind].params:
        value = list(checked[p.name]) if isinstance(checked[p.name], tuple) else checked[p.name]
        assert defaults[p.name] == value, p.name
        if p.service_only:
            assert p.option not in actions
            continue
        assert p.option in actions, f"{kind}: no CLI option {p.option} for API key {p.name}"
        if p.type == "bool":
            assert f"--no-{p.option[2:]}" in actions
        args = build_parser().parse_args([kind, "in.step", "-o", "out.stl"] if "-o" in actions else [kind, "in.step"])
        assert getattr(args, p.name) is None  # unset on the CLI: the default comes from check(), as over HTTP


@pytest.mark.parametrize("kind", list(KINDS))
def test_bounds_are_the_same_for_the_api_and_the_cli(kind):
    model = PARAMS_MODEL[kind]
    for p in KINDS[kind].params:
        if p.type not in ("float", "int"):
            continue
        for bad in _outside(p):
            with pytest.raises(ValidationError):
                model.model_validate({p.name: bad})
            with pytest.raises(AmprepError):
                check(kind, {p.name: bad})
        for good in (v for v in (p.ge, p.le) if v is not None):
            value = int(good) if p.type == "int" else good
            assert model.model_validate({p.name: value}).model_dump()[p.name] == value
            assert check(kind, {p.name: value})[p.name] == value
        if p.type == "float":
            for bad in (math.inf, math.nan):
                with pytest.raises(ValidationError):
                    model.model_validate({p.name: bad})
                with pytest.raises(AmprepError):
                    check(kind, {p.name: bad})


def test_cross_field_and_type_checks():
    with pytest.raises(AmprepError, match="zero vector"):
        check("analyze", {"build_dir": [0, 0, 0]})
    with pytest.raises(AmprepError, match="not a parameter"):
        check("convert", {"layer": 0.2})
    with pytest.raises(AmprepError, match="not a parameter"):
        check("convert", {"reuse": False})  # service-only keys are not the library's
    assert check("refine", {"faces": [3, 7], "build_dir": [1, 0, 0]})["faces"] == (3, 7)
    with pytest.raises(AmprepError):
        check("refine", {"ratios": "3:4"})
    assert parse_cli_value(KINDS["refine"].param("faces"), "3,7") == [3, 7]
    assert parse_cli_value(KINDS["analyze"].param("build_dir"), "0,1,0") == [0.0, 1.0, 0.0]
    with pytest.raises(AmprepError):
        parse_cli_value(KINDS["refine"].param("iterations"), "1.5")


def test_values_fill_the_geometry_dataclasses_by_name():
    from amprep.geometry.measure.analysis import AnalysisParams
    from amprep.geometry.meshing.params import MeshParams
    from amprep.geometry.refine.compare import RefineParams

    values = check("refine", {"tolerance": 0.05, "faces": [1], "layer": 0.1, "occt_edges": True})
    mp, rp = build(MeshParams, values), build(RefineParams, values)
    assert (mp.tolerance, mp.occt_edges, rp.faces, rp.layer) == (0.05, True, (1,), 0.1)
    a = build(AnalysisParams, check("analyze", {"sample_order": 25}))
    assert a.sample_order == 25 and build(MeshParams, check("analyze", {"sample_order": 25})).check_order == 6


def test_the_client_knows_every_main_artifact():
    for kind, spec in KINDS.items():
        for name in spec.artifacts:
            assert main_artifact({"kind": kind, "artifacts": [{"name": name}, {"name": "report.json"}]}) in (
                name, "report.json")
    assert main_artifact({"kind": "refine", "artifacts": [{"name": "refined.3mf"}]}) == "refined.3mf"


def test_docs_params_md_is_generated_from_the_definition():
    assert (ROOT / "docs" / "params.md").read_text(encoding="utf-8") == reference.markdown(), \
        "docs/params.md is stale: run `python -m amprep.jobs.reference > docs/params.md`"


def test_cli_output_format_comes_from_the_extension_unless_given(capsys):
    from amprep.cli import _job_values

    parse = build_parser().parse_args
    assert _job_values("convert", parse(["convert", "in.step", "-o", "out.3MF"]))["format"] == "3mf"
    assert _job_values("convert", parse(["convert", "in.step", "-o", "o.stl", "--format", "stl"]))["format"] == "stl"
    with pytest.raises(AmprepError, match="disagree|but -o"):
        _job_values("convert", parse(["convert", "in.step", "-o", "o.stl", "--format", "3mf"]))
    with pytest.raises(AmprepError, match="must end in"):
        _job_values("refine", parse(["refine", "in.step", "-o", "o.obj"]))
    with pytest.raises(SystemExit) as done:
        parse(["--version"])
    assert done.value.code == 0 and capsys.readouterr().out.startswith("amprep ")
