"""``mcmcfit bench render``: a tiny run through the command line, and the synthetic model."""

from __future__ import annotations

import re

import numpy as np
import pytest

from mcmcfit.bench.render_bench import KINDS
from mcmcfit.bench.synthetic_face import synthetic_face_model
from mcmcfit.cli import main

pytestmark = pytest.mark.embree


def test_bench_render_smoke(capsys):
    assert main(["bench", "render", "--sizes", "24", "--steps", "2", "--warmup", "1",
                 "--grid", "40", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"cores: \d+ +ray-cast threads: [12] +embree update: (refit|rebuild)", out)
    assert re.search(r"yardstick: 1-thread ray cast .* \d+\.\d ms", out)
    rows = [line.split() for line in out.splitlines()
            if re.match(r"\s*\d+x\d+ +[a-z]+ +\d+\.\d+ ", line)]
    assert [(r[0], r[1]) for r in rows] == [(s, k) for s in ("24x24",) for k in KINDS]
    for r in rows:
        ours, no_spec, extra, naive, ratio = (float(x) for x in r[2:7])
        assert all(np.isfinite(v) and v > 0 for v in (ours, no_spec, naive, ratio))
        assert extra == pytest.approx(ours - no_spec, abs=0.011)
        assert ratio == pytest.approx(naive / ours, rel=0.05, abs=0.06)  # printed rounded
        assert 0.3 < float(r[7].rstrip("%")) / 100 < 0.9  # face coverage
        mixed, mixed_mean = float(r[8]), float(r[9])  # the kind's steps in the mixed chain
        assert np.isfinite(mixed) and np.isfinite(mixed_mean) and mixed > 0 and mixed_mean > 0
    assert re.search(r"24x24 mixed .*: \d+ steps/s, naive \d+\.\d steps/s \(\d+x\)", out)
    # no reference figures at 24x24: the comparison with performance-notes.md is left out
    assert "against performance-notes" not in out


def test_against_notes_scales_the_reference_by_the_embree_yardstick():
    from mcmcfit.bench.render_report import BenchResult, BenchRow, format_table

    rows = [BenchRow(250, "shape", 20.0, 19.0, 200.0, 0.6, 21.0, 22.0, 210.0),
            BenchRow(250, "light", 1.0, 0.8, 200.0, 0.6, 2.0, 2.5, 210.0)]
    result = BenchResult(rows, 2, 2, "refit", 40, 0.5, 53824, 106722, 14.0, 13.2,
                         (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    out = format_table(result)
    assert "13.2 / 6.6 = 2.00" in out
    line = next(x for x in out.splitlines() if re.match(r"250x250 +shape +10\.2 ", x))
    assert line.split()[2:] == ["10.2", "20.40", "20.00", "0.98"]  # 20 / (10.2 * 2)


def test_bench_render_rejects_bad_options(capsys):
    assert main(["bench", "render", "--steps", "0", "--quiet"]) == 2
    assert "--steps" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "render", "--sizes", "big"])


def test_synthetic_face_model_is_deterministic_with_orthonormal_bases():
    a = synthetic_face_model(3, 30, 40)
    b = synthetic_face_model(3, 30, 40)
    assert a.n_vertices == 1200 and a.n_triangles == 2 * 29 * 39
    np.testing.assert_array_equal(a.shape.basis, b.shape.basis)
    for part in (a.shape, a.expression, a.diffuse, a.specular):
        np.testing.assert_allclose(part.basis.T @ part.basis, np.eye(part.rank), atol=1e-10)
    assert (a.shape.rank, a.expression.rank, a.diffuse.rank, a.specular.rank) == (50, 5, 50, 50)
    assert a.shared_albedo
    # counter-clockwise seen from outside: face normals point away from the centre
    v, t = a.vertices, a.triangles
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    assert (np.einsum("ij,ij->i", n, v[t].mean(1)) > 0).mean() > 0.99


def test_synthetic_face_model_default_is_bfm_sized():
    m = synthetic_face_model()
    assert m.n_vertices >= 53_000 and m.n_triangles >= 106_000
    mean = m.diffuse.mean
    assert np.isfinite(mean).all() and 0.1 < mean.min() < mean.max() < 1
