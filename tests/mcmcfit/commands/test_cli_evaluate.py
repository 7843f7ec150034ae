"""``mcmcfit evaluate`` end to end in its small CI configuration, and its input errors.

The small configuration: 2 held-out subjects of the default model's population,
the ``ambient`` scene, the intrinsic model, 80 px, the random-walk sampler with
a short schedule (two fits on two workers). It checks the table's structure,
the outputs, that the posterior mean beats the model mean, that a second run
fits nothing (resumable) and that ``--score-only`` re-scores.
"""

from __future__ import annotations

import json
import time

import pytest

from mcmcfit.cli import main

SMALL = ["--held-out", "2", "--scenes", "ambient", "--models", "intrinsic", "--size", "80",
         "--sampler", "random-walk", "--steps", "400", "--landmark-steps", "300",
         "--chains", "2", "--workers", "2", "--quiet"]
OUTPUTS = ("cases.json", "table.md", "table.csv", "calibration.png", "accuracy_time.png",
           "report.html", "results.json")


@pytest.fixture(scope="module")
def small_eval(default_model_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("evaluate") / "EVAL"
    t0 = time.perf_counter()
    code = main(["evaluate", "-o", str(out), *SMALL])
    seconds = time.perf_counter() - t0
    print(f"mcmcfit evaluate (CI configuration): {seconds:.0f} s")
    return out, code


def test_small_configuration_writes_table_one(small_eval, capsys):
    out, code = small_eval
    assert code == 0
    for name in OUTPUTS:
        assert (out / name).is_file(), name
    results = json.loads((out / "results.json").read_text())
    assert results["settings"]["n_held_out"] == 2 and results["settings"]["scenes"] == ["ambient"]
    assert results["population"]["held_out"] == [60, 61]
    assert [r["case"] for r in results["rows"]] == ["ambient/subject060", "ambient/subject061"]
    assert all(r["status"] == "ok" for r in results["rows"])
    for r in results["rows"]:
        assert r["seed"] is not None and r["model_sha256"] and r["version"]
        assert r["projection_floor"]["diffuse"] > 0
        assert set(r["diffuse"]["coverage"]) == {"0.5", "0.8", "0.9", "0.95"}
        assert r["diffuse"]["regions"]
        # accuracy at the fit's convergence checks: the last one scores (a thinned set of)
        # the same draws as the final row, at the wall time of that check
        pts = r["checkpoints"]
        assert [p["kept_steps"] for p in pts] == [c["kept_steps"] for c in r["checks"]]
        assert pts and pts[-1]["seconds"] <= r["wall_s"]
        assert pts[-1]["mse"] == pytest.approx(r["diffuse"]["mse"], rel=0.15)
        assert 0.0 <= pts[-1]["coverage_90"] <= 1.0
    (row,) = results["table"]
    assert (row["scene"], row["model"], row["n"], row["failed"]) == ("ambient", "intrinsic", 2, 0)
    # the fit recovers more of the held-out albedo than the model mean does
    assert row["mse_mean"] < 0.95 * row["mse_model_mean_mean"]
    assert row["floor_mean"] < row["mse_mean"]
    md = (out / "table.md").read_text()
    assert "## scene `ambient`" in md and "| model | reconstruction | model mean | n |" in md
    csv_lines = (out / "table.csv").read_text().strip().splitlines()
    assert len(csv_lines) == 2 and csv_lines[0].startswith("scene,model,n,failed,missing,mse_mean,mse_sd")
    html = (out / "report.html").read_text()
    assert html.count("<tr>") == 2 and "posterior sd" in html and "true albedo" in html


def test_second_run_fits_nothing_and_score_only_rescores(small_eval, capsys):
    out, _ = small_eval
    before = (out / "fits" / "intrinsic" / "batch.jsonl").read_text()
    assert main(["evaluate", "-o", str(out), *SMALL]) == 0
    assert (out / "fits" / "intrinsic" / "batch.jsonl").read_text() == before
    old = json.loads((out / "results.json").read_text())["table"]
    assert main(["evaluate", "-o", str(out), "--score-only", *SMALL]) == 0
    assert json.loads((out / "results.json").read_text())["table"] == old


@pytest.mark.parametrize("argv, message", [
    (["--scenes", "moonlight"], "unknown scene(s) moonlight"),
    (["--models", "bfm"], "unknown model(s) bfm"),
    (["--scenes", "dark", "--held-out", "2"], "use --held-out 6"),
    (["--size", "8"], "--size must be at least 32"),
    (["--score-only"], "no cases.json"),
    (["--model-colour", "srgb"], "set per model"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, argv, message):
    out = tmp_path / "EVAL"
    assert main(["evaluate", "-o", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists() or not any(out.iterdir())


def test_other_settings_in_an_existing_folder_lose_nothing(small_eval, capsys):
    out, _ = small_eval
    before = {p: p.read_bytes() for p in (out / "cases.json", out / "results.json")}
    assert main(["evaluate", "-o", str(out), *SMALL, "--held-out", "3"]) == 2
    assert "other settings" in capsys.readouterr().err
    assert {p: p.read_bytes() for p in before} == before
