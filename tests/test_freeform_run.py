"""``ncadapt.freeform.run``: the whole job in one call gives the numbers and files of
``ncadapt compensate`` on the same input (the command is the peer)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from ncadapt import freeform
from ncadapt.cli import main
from ncadapt.sim import freeform as ff


def _same(result, j):
    assert result.analysis.moran.I == pytest.approx(j["moran"]["I"], rel=1e-12)
    assert result.analysis.verdict.systematic == j["verdict"]["systematic"]
    dd = result.decomposition.as_dict()
    assert dd["systematic"] == pytest.approx(j["systematic"], rel=1e-12)
    c = result.correction.as_dict()
    assert c["round"] == j["correction"]["round"] and c["kind"] == j["correction"]["kind"]
    grids = [c] if c["kind"] == "frame" else c["faces"]
    their = [j["correction"]] if c["kind"] == "frame" else j["correction"]["faces"]
    for a, b in zip(grids, their, strict=True):
        np.testing.assert_allclose(a["df"], b["df"], rtol=0, atol=1e-15)
        assert a["u"] == b["u"] and a["v"] == b["v"]


def test_run_is_the_command(tmp_path):
    part = ff.demo_part()
    p, n = ff.probe_points(part, 5.0, 2.5)
    err = ff.ErrorModel(part, (("curvature", 0.08),))
    prog = tmp_path / "part.ngc"
    prog.write_text(ff.finishing_program(part, 4.0, 0.5, 1.0))
    from ncadapt import nc

    z = ff.machine(nc.read(prog), part, err, 4.0)
    m = ff.measure(z, p, n, noise=0.005, seed=3)
    csv = tmp_path / "m.csv"
    csv.write_text(
        "x,y,z,i,j,k,mx,my,mz\n"
        + "".join(
            ",".join(f"{v!r}" for v in (*a, *b, *c)) + "\n" for a, b, c in zip(p.tolist(), n.tolist(), m.tolist())
        )
    )
    js, out = tmp_path / "c.json", tmp_path / "cli.ngc"
    args = ["compensate", str(csv), "--program", str(prog), "-o", str(out), "--tool-radius", "4", "--outside", "clamp"]
    r = CliRunner().invoke(main, [*args, "--json", str(js)])
    assert r.exit_code == 0, r.output
    res = freeform.run(csv, program=prog, output=tmp_path / "run.ngc", tool_radius=4.0, outside="clamp")
    _same(res, json.loads(js.read_text()))
    assert (tmp_path / "run.ngc").read_text() == out.read_text()
    assert res.files == {"program": tmp_path / "run.ngc"} and res.frame.names == ("x", "y")
    # a second round from the first's JSON, and from the first's result
    m2 = ff.measure(z, p, n, noise=0.005, seed=4)
    csv.write_text(
        "x,y,z,i,j,k,mx,my,mz\n"
        + "".join(
            ",".join(f"{v!r}" for v in (*a, *b, *c)) + "\n" for a, b, c in zip(p.tolist(), n.tolist(), m2.tolist())
        )
    )
    js2 = tmp_path / "c2.json"
    r = CliRunner().invoke(main, ["compensate", str(csv), "--previous", str(js), "--gain", "0.8", "--json", str(js2)])
    assert r.exit_code == 0, r.output
    for prev in (js, res.correction):
        _same(freeform.run(csv, previous=prev, gain=0.8), json.loads(js2.read_text()))


def test_run_with_a_cad_nominal(tmp_path):
    pytest.importorskip("OCP")
    from test_rounds import _plate

    step = _plate(tmp_path / "plate.step")
    x, y = (g.ravel() for g in np.meshgrid(np.arange(2.0, 58.1, 2.0), np.arange(2.0, 38.1, 2.0), indexing="ij"))
    z = 5.0 + 0.02 + 0.0005 * x + np.random.default_rng(1).normal(0, 0.005, len(x))
    csv = tmp_path / "a.csv"
    csv.write_text("x,y,z\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in zip(x.tolist(), y.tolist(), z.tolist())))
    js, cli_part = tmp_path / "c.json", tmp_path / "cli.step"
    r = CliRunner().invoke(
        main, ["compensate", str(csv), "--nominal", str(step), "--part", str(cli_part), "--json", str(js)]
    )
    assert r.exit_code == 0, r.output
    res = freeform.run(csv, nominal=step, part=tmp_path / "run.step")
    j = json.loads(js.read_text())
    _same(res, j)
    assert res.alignment.as_dict()["translation"] == j["alignment"]["translation"] and res.files["part"].exists()
    assert res.compensation.ids == j["faces"] == [1]
