"""The specgen command: writes the plot and the JSON curves, prints a table."""

import argparse
import json

import pytest

from albedo_model.errors import InputError
from mcmcfit.commands import model_specgen as specgen


def _args(argv):
    parser = argparse.ArgumentParser()
    specgen.add_arguments(parser)
    return parser.parse_args(argv)


def test_specgen_writes_plot_and_json(tmp_path, monkeypatch, stand_in_head, capsys):
    monkeypatch.setattr(specgen, "_template", lambda: stand_in_head)
    out, js = tmp_path / "specgen.png", tmp_path / "specgen.json"
    argv = ["--subjects", "4", "--seed", "1", "-o", str(out), "--json", str(js)]
    assert specgen.run(_args(argv)) == 0
    assert out.stat().st_size > 1000
    data = json.loads(js.read_text())
    assert data["n_subjects"] == 4 and data["augmented"]
    assert data["components"] == list(range(6))  # 3 training subjects x 2 - 1
    assert set(data["fit_mean"]) == {"independent", "concatenated", "transferred"}
    text = capsys.readouterr().out
    assert "transferred" in text and str(out) in text


def test_specgen_rejects_too_few_subjects(monkeypatch, stand_in_head, tmp_path):
    monkeypatch.setattr(specgen, "_template", lambda: stand_in_head)
    with pytest.raises(InputError, match="at least 3"):
        specgen.run(_args(["--subjects", "2", "-o", str(tmp_path / "x.png")]))
