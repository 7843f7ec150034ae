"""``mcmcfit batch --group-by person``: each person's photographs fitted jointly, one folder per person.

A tiny LFW-like tree of one small synthetic face model: a person with three
photographs of one identity (other yaw and light each; ``--max-per-person 2``
keeps two), a person with one photograph (a single fit), and a person at the
top of INPUT (``Name_0001.png``, ``Name_0002.png``) one of whose photographs is
corrupt (the joint fit fails, the batch goes on). Checked: the folders, the
journals, the report's rows per person, the re-run, and the options a joint
fit cannot take.
"""

from __future__ import annotations

import csv
import json
from pathlib import PurePosixPath

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from albedo_model.io.image_io import write_png
from albedo_model.io.momo_h5 import write_model_h5
from albedo_model.io.tlms import Landmark, write_tlms
from albedo_model.params import MoMoCoefficients, SHLight
from mcmcfit.batch.discovery import BatchItem, group_by_person, person_of
from mcmcfit.batch.journal import read_journal
from mcmcfit.cli import main

SHORT = ["--max-steps", "100", "--landmark-steps", "150", "--warmup-steps", "60", "--serial",
         "--quiet"]


def _photograph(model, path, identity, yaw, k, rng):
    truth = scene(64, 64, yaw=yaw, coefficients=identity._replace(
        expression=rng.normal(0, 0.5, 2)))._replace(
        environment_map=SHLight.frontal(0.7 + 0.1 * k, 0.3 * (-1) ** k))
    image, clicked = synthetic_target(model, truth)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_png(path, image)
    write_tlms(path.with_suffix(".tlms"), [Landmark(n, (float(p[0]), float(p[1])), True)
                                           for n, p in clicked.items()])
    return truth


@pytest.fixture(scope="module")
def batch(tmp_path_factory):
    root = tmp_path_factory.mktemp("group")
    model = small_face_model()
    write_model_h5(model, root / "small.h5")
    rng = np.random.default_rng(3)
    src = root / "lfw"
    people = {"Ann_Alpha": [src / "Ann_Alpha" / f"Ann_Alpha_{i:04d}.png" for i in (1, 2, 3)],
              "Bob_Beta": [src / "Bob_Beta" / "Bob_Beta_0001.png"],
              "Cy_Gamma": [src / f"Cy_Gamma_{i:04d}.png" for i in (1, 2)]}
    truths = {}
    for person, paths in people.items():
        identity = MoMoCoefficients(rng.normal(size=4), rng.normal(size=3), np.zeros(2))
        truths[person] = [_photograph(model, p, identity, yaw, k, rng)
                          for k, (p, yaw) in enumerate(zip(paths, (0.3, -0.3, 0.1)))]
    people["Cy_Gamma"][1].write_bytes(b"\x89PNG\r\n\x1a\n not an image")
    out = root / "OUT"
    argv = ["batch", str(src), "-o", str(out), "--model", str(root / "small.h5"),
            "--group-by", "person", "--max-per-person", "2", "--workers", "1", "--seed", "4",
            *SHORT]
    rc = main(argv)
    return {"root": root, "src": src, "out": out, "argv": argv, "rc": rc, "truths": truths,
            "model": model}


def test_person_of_reads_lfw_folders_and_numbered_names():
    assert person_of(PurePosixPath("Ann_Alpha/Ann_Alpha_0002")) == PurePosixPath("Ann_Alpha")
    assert person_of(PurePosixPath("Ann_Alpha_0002")) == PurePosixPath("Ann_Alpha")
    assert person_of(PurePosixPath("a/b/c_1")) == PurePosixPath("a/b")
    assert person_of(PurePosixPath("portrait")) == PurePosixPath("portrait")
    items = [BatchItem(None, f"P/P_{i}.png", PurePosixPath(f"P/P_{i}"), None) for i in range(5)]
    groups, skipped = group_by_person(items, max_per_person=3)
    assert [len(g.items) for g in groups] == [3]
    assert [s.relative for s in skipped] == ["P/P_3", "P/P_4"]
    assert "first 3 are fitted jointly" in skipped[0].reason


def test_one_folder_per_person_joint_where_there_are_several(batch):
    out = batch["out"]
    assert batch["rc"] == 1  # Cy_Gamma's corrupt photograph fails its joint fit
    assert sorted(p.parent.name for p in out.rglob("summary.json")) == ["Ann_Alpha", "Bob_Beta"]
    ann = json.loads((out / "Ann_Alpha" / "summary.json").read_text())
    assert [im["image"].rsplit("/", 1)[-1] for im in ann["images"]] == [
        "Ann_Alpha_0001.png", "Ann_Alpha_0002.png"]
    for k in (0, 1):
        assert (out / "Ann_Alpha" / f"image{k}" / "fit.png").is_file()
    with np.load(out / "Ann_Alpha" / "posterior.npz") as z:
        assert z["visible_images"].shape[0] == 2
    bob = json.loads((out / "Bob_Beta" / "summary.json").read_text())
    assert "images" not in bob and (out / "Bob_Beta" / "fit.png").is_file()  # a single fit


def test_journals_and_report_have_a_row_per_person(batch, tmp_path):
    out = batch["out"]
    done = {r["relative"]: r for r in read_journal(out / "batch.jsonl")}
    assert set(done) == {"Ann_Alpha", "Bob_Beta"}
    assert done["Ann_Alpha"]["images"] == ["Ann_Alpha/Ann_Alpha_0001.png",
                                           "Ann_Alpha/Ann_Alpha_0002.png"]
    assert done["Ann_Alpha"]["n_images"] == 2 and done["Bob_Beta"]["n_images"] == 1
    ann = json.loads((out / "Ann_Alpha" / "summary.json").read_text())
    assert done["Ann_Alpha"]["landmark_rms_px"] == pytest.approx(
        np.mean([im["landmark_rmse_px"] for im in ann["images"]]))
    fails = {r["relative"]: r for r in read_journal(out / "failures.jsonl")}
    assert fails["Ann_Alpha/Ann_Alpha_0003"]["status"] == "skipped"
    assert "--max-per-person" in fails["Ann_Alpha/Ann_Alpha_0003"]["reason"]
    assert fails["Cy_Gamma"]["status"] == "failed"
    assert fails["Cy_Gamma"]["images"] == ["Cy_Gamma_0001.png", "Cy_Gamma_0002.png"]
    assert "not a readable image" in fails["Cy_Gamma"]["reason"]
    table = tmp_path / "rows.csv"
    assert main(["batch-report", str(out), "-o", str(tmp_path / "r.html"),
                 "--csv", str(table)]) == 0
    rows = {(r["subject"], r["status"], r["n_images"]) for r in csv.DictReader(table.open())}
    assert rows == {("Ann_Alpha", "ok", "2"), ("Bob_Beta", "ok", "1"),
                    ("Ann_Alpha", "skipped", ""), ("Cy_Gamma", "failed", "")}


def test_rerun_keeps_complete_people(batch, capsys):
    out = batch["out"]
    stamp = (out / "Ann_Alpha" / "summary.json").stat().st_mtime_ns
    assert main(batch["argv"]) == 1
    assert "0 people fitted, 1 failed, 2 already complete" in capsys.readouterr().err
    assert (out / "Ann_Alpha" / "summary.json").stat().st_mtime_ns == stamp


def test_options_a_joint_fit_cannot_take(batch, tmp_path, capsys):
    base = ["batch", str(batch["src"]), "-o", str(tmp_path / "x"), "--model",
            str(batch["root"] / "small.h5"), "--group-by", "person", "--quiet"]
    assert main([*base, "--face-box-default"]) == 2
    assert "not a face box" in capsys.readouterr().err
    assert main([*base, "--max-per-person", "1"]) == 2
    assert "--max-per-person must be 2 to 8" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
