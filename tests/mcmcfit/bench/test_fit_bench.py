"""``mcmcfit bench fit``: a tiny schedule through the command line; proposal kinds."""

from __future__ import annotations

import json
import math
import re

import pytest

from mcmcfit.bench.fit_bench import proposal_kind
from mcmcfit.cli import main

pytestmark = pytest.mark.embree


def test_proposal_kind_strips_scales_and_centring():
    assert proposal_kind("albedo-0.1") == "albedo"
    assert proposal_kind("albedo-caricature-0.2") == "albedo-caricature"
    assert proposal_kind("focal-0.05@left.lips.corner") == "focal"
    assert proposal_kind("sh-perturb-fixed-0.001") == "sh-perturb-fixed"
    assert proposal_kind("light-albedo-1e-05") == "light-albedo"
    assert proposal_kind("sh-solver") == "sh-solver"


def test_bench_fit_tiny_schedule_and_ess_per_second_against_the_reference(default_model_file,
                                                                           tmp_path, capsys):
    """One tiny run (a bench fit costs ~1 min of the suite): the report, curve and mixing."""
    png, js = tmp_path / "curve.png", tmp_path / "bench.json"
    assert main(["bench", "fit", "--steps", "60", "--warmup-steps", "30", "--landmark-steps", "30",
                 "--size", "96", "--checkpoints", "30,60", "-o", str(png), "--json", str(js),
                 "--quiet", "--mixing-cases", "demo"]) == 0
    out = capsys.readouterr().out
    assert re.search(r"wall time \d+\.\d s: setup .* stage 1 .* stage 2 .*steps/s\)", out)
    assert re.search(r"reference pipeline ~20 min per fit: \d+\.\dx faster", out)
    assert "time per proposal kind, stage 2" in out and "accuracy vs time" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads(js.read_text())
    curve = data["curve"]
    assert [r["steps"] for r in curve] == [30, 60]
    assert curve[0]["wall_s"] <= curve[1]["wall_s"] <= data["timings"]["total_s"] + 1e-6
    assert all(math.isfinite(r["rmse"]) and 0 <= r["coverage"] <= 1 for r in curve)
    kinds = data["stage2_kinds"]
    assert sum(k["steps"] for k in kinds.values()) == 60 * data["config"]["chains"]
    # the per-kind times add up to the stage's wall time (minus loop set-up)
    total = sum(k["seconds"] for k in kinds.values())
    assert total <= data["timings"]["stage2_s"] + 1e-6 and total > 0.5 * data["timings"]["stage2_s"]
    # the ESS-per-second comparison, the reference on the posterior the default measured
    assert "effective samples per second" in out and re.search(r"demo\s+ratio\s+\d", out)
    mixing = data["mixing"]["demo"]
    for label in ("default", "reference"):
        d = mixing[label]
        assert d["kept_steps"] == 60 and d["min_ess_per_s"] > 0 and d["kept_wall_s"] > 0
    assert mixing["reference"]["noise"]["sigma"] == mixing["default"]["noise"]["sigma"]
    assert mixing["reference"]["noise"]["source"] == "fixed"
    assert math.isclose(mixing["ratio_min_ess_per_s"], mixing["default"]["min_ess_per_s"]
                        / mixing["reference"]["min_ess_per_s"])


def test_bench_fit_rejects_a_missing_output_folder(tmp_path, capsys):
    assert main(["bench", "fit", "--steps", "5", "-o", str(tmp_path / "no" / "x.png"),
                 "--quiet"]) == 2
    assert "does not exist" in capsys.readouterr().err


def test_bench_fit_rejects_unknown_mixing_cases(tmp_path, capsys):
    assert main(["bench", "fit", "--steps", "5", "--mixing-cases", "nope", "--quiet",
                 "--landmark-steps", "5", "--size", "64", "--checkpoints", "5"]) == 2
    assert "unknown --mixing-cases" in capsys.readouterr().err
