"""``mcmcfit batch`` end to end on a tiny LFW-like tree of synthetic faces (default model).

Non-slow: one short batch on two workers with a corrupted image, bad landmarks and an
image without landmarks, re-run, report. Slow: SIGKILL of the batch and resume; the
same batch on a Dask LocalCluster gives the numbers of the process pool.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from batch_tree import lfw_like_tree, write_case

from albedo_model.io.model_files import load_model
from mcmcfit.batch.journal import read_journal
from mcmcfit.batch.records import albedo_digest
from mcmcfit.batch.seeds import image_seed
from mcmcfit.cli import main
from mcmcfit.outputs import OUTPUT_FILES

SHORT = ["--steps", "40", "--warmup-steps", "20", "--landmark-steps", "40", "--chains", "1",
         "--quiet"]
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def model(default_model_file):
    return load_model(default_model_file)


def _temporaries(out: Path) -> list[Path]:
    return [p for p in out.rglob(".*") if p.is_dir()]


def _result_folders(out: Path) -> list[str]:
    return sorted(str(p.parent.relative_to(out)) for p in out.rglob("summary.json"))


@pytest.fixture(scope="module")
def mixed_batch(model, default_model_file, tmp_path_factory):
    root = tmp_path_factory.mktemp("batch")
    src = root / "lfw"
    good = lfw_like_tree(model, src, 2, size=80)
    corrupt = write_case(model, src / "Dee_Delta" / "Dee_Delta_0001.png", seed=7, size=80)
    corrupt.write_bytes(b"\x89PNG\r\n\x1a\n this is not an image")
    bad_lm = write_case(model, src / "Dee_Delta" / "Dee_Delta_0002.png", seed=8, size=80)
    bad_lm.with_suffix(".tlms").write_text("left.eye.corner_outer 1 12.5 oops\n")
    no_lm = write_case(model, src / "Eve_Eps" / "Eve_Eps_0001.png", seed=9, size=80)
    no_lm.with_suffix(".tlms").unlink()
    out = root / "OUT"
    argv = ["batch", str(src), "-o", str(out), "--model", str(default_model_file),
            "--workers", "2", "--seed", "11", *SHORT]
    t0 = time.perf_counter()
    rc = main(argv)
    first_s = time.perf_counter() - t0
    return {"src": src, "out": out, "good": good, "argv": argv, "rc": rc, "seconds": first_s}


def test_batch_fits_good_images_and_records_failures(mixed_batch):
    out, rc = mixed_batch["out"], mixed_batch["rc"]
    assert rc == 1  # two images failed
    assert _result_folders(out) == ["Ann_Alpha/Ann_Alpha_0001", "Bob_Beta/Bob_Beta_0001"]
    for rel in _result_folders(out):
        assert set(OUTPUT_FILES) <= {p.name for p in (out / rel).iterdir()}
    assert not _temporaries(out)
    fails = {r["path"]: r for r in read_journal(out / "failures.jsonl")}
    assert set(fails) == {"Dee_Delta/Dee_Delta_0001.png", "Dee_Delta/Dee_Delta_0002.png",
                          "Eve_Eps/Eve_Eps_0001.png"}
    assert fails["Dee_Delta/Dee_Delta_0001.png"]["status"] == "failed"
    assert "not a readable image" in fails["Dee_Delta/Dee_Delta_0001.png"]["reason"]
    assert fails["Dee_Delta/Dee_Delta_0002.png"]["status"] == "failed"
    assert "'oops' is not a number" in fails["Dee_Delta/Dee_Delta_0002.png"]["reason"]
    assert fails["Eve_Eps/Eve_Eps_0001.png"]["status"] == "skipped"
    assert "no landmark file" in fails["Eve_Eps/Eve_Eps_0001.png"]["reason"]
    assert not (out / "Dee_Delta" / "Dee_Delta_0001").exists()  # nothing partial


def test_batch_journal_lines_match_the_result_folders(mixed_batch):
    out = mixed_batch["out"]
    lines = read_journal(out / "batch.jsonl")
    assert sorted(r["relative"] for r in lines) == _result_folders(out)
    for r in lines:
        folder = out / r["relative"]
        summary = json.loads((folder / "summary.json").read_text())
        # the image's seed derives from the root seed and the relative path
        assert summary["seed"] == r["seed"] == image_seed(11, r["relative"])
        acc = summary["acceptance"]
        assert r["acceptance"] == pytest.approx(sum(v["accepted"] for v in acc.values())
                                                / sum(v["proposed"] for v in acc.values()))
        assert r["landmark_rms_px"] == pytest.approx(summary["landmark_rmse_px"])
        assert r["landmark_rms_px"] < 5.0  # true landmarks of the synthetic face, 80 px image
        with np.load(folder / "posterior.npz") as z:
            vis = z["visible"]
            assert r["albedo"]["diffuse_mean_rgb"] == pytest.approx(
                z["diffuse_mean"][vis].astype(float).mean(0).tolist())
        assert r["albedo"] == albedo_digest(folder / "posterior.npz")
        assert r["seconds"] > 0 and r["pid"] != os.getpid()


def test_rerun_skips_complete_images_and_retries_failures(mixed_batch, capsys):
    out = mixed_batch["out"]
    stamps = {rel: (out / rel / "summary.json").stat().st_mtime_ns for rel in _result_folders(out)}
    n_fail = len(read_journal(out / "failures.jsonl"))
    assert main(mixed_batch["argv"]) == 1
    assert "0 fitted, 2 failed, 2 already complete, 1 skipped" in capsys.readouterr().err
    assert {rel: (out / rel / "summary.json").stat().st_mtime_ns
            for rel in _result_folders(out)} == stamps
    assert len(read_journal(out / "batch.jsonl")) == 2
    assert len(read_journal(out / "failures.jsonl")) == n_fail + 2  # skipped one not repeated


def test_batch_report_html_and_csv(mixed_batch, tmp_path):
    out = mixed_batch["out"]
    html, table = out / "summary.html", tmp_path / "summary.csv"
    assert main(["batch-report", str(out), "-o", str(html), "--csv", str(table)]) == 0
    rows = list(csv.DictReader(table.open()))
    assert sorted((r["subject"], r["status"]) for r in rows) == [
        ("Ann_Alpha", "ok"), ("Bob_Beta", "ok"), ("Dee_Delta", "failed"), ("Dee_Delta", "failed"),
        ("Eve_Eps", "skipped")]
    journal = {r["relative"]: r for r in read_journal(out / "batch.jsonl")}
    for r in rows:
        if r["status"] == "ok":
            assert float(r["acceptance"]) == pytest.approx(journal[r["relative"]]["acceptance"])
    page = html.read_text()
    assert page.count("data:image/png;base64,") == 5
    assert 'href="Ann_Alpha/Ann_Alpha_0001/report.html"' in page
    assert "not a readable image" in page


def _children(pid: int) -> list[int]:
    """Child pids of ``pid`` (Linux /proc)."""
    kids = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        kids += [int(k) for k in (task / "children").read_text().split()]
    return kids


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state != "Z"


def _batch_cmd(src: Path, out: Path, model_file: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "mcmcfit", "batch", str(src), "-o", str(out),
            "--model", str(model_file), *extra]


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="needs Linux /proc")
def test_sigkill_mid_batch_then_rerun_completes_without_duplicates(model, default_model_file,
                                                                   tmp_path):
    src = tmp_path / "lfw"
    lfw_like_tree(model, src, 5, size=80)
    out = tmp_path / "OUT"
    cmd = _batch_cmd(src, out, default_model_file, "--workers", "1", "--steps", "150",
                     "--landmark-steps", "100", "--chains", "1", "--quiet")
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    # kill while the worker is writing an image's outputs (into its hidden temporary
    # folder), after at least one image is finished
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None:
        if read_journal(out / "batch.jsonl") and _temporaries(out):
            break
        time.sleep(0.05)
    assert proc.poll() is None, "the batch finished before it could be killed"
    workers = _children(proc.pid)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    time.sleep(1.0)
    # the worker died with its parent (PR_SET_PDEATHSIG): nothing renames into OUT later
    assert workers and not any(_alive(pid) for pid in workers)
    assert _temporaries(out)  # the killed image's partial folder is left behind...
    done_before = _result_folders(out)
    assert 1 <= len(done_before) < 5
    rerun = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert f"{len(done_before)} already complete" in rerun.stderr
    folders = _result_folders(out)
    assert len(folders) == 5 and not _temporaries(out)  # ...and removed by the re-run
    lines = [r["relative"] for r in read_journal(out / "batch.jsonl")]
    assert sorted(lines) == folders  # one line per image, none twice
    assert not read_journal(out / "failures.jsonl")


def _comparable(summary: dict) -> dict:
    keep = ("seed", "best", "best_posterior", "acceptance", "acceptance_stage1",
            "landmark_rmse_px", "ess", "rhat", "model_sha256")
    return {k: summary[k] for k in keep}


@pytest.mark.slow
def test_dask_local_cluster_gives_the_numbers_of_the_process_pool(model, default_model_file,
                                                                  tmp_path):
    pytest.importorskip("distributed")
    src = tmp_path / "lfw"
    lfw_like_tree(model, src, 3, size=80)
    common = ["--model", str(default_model_file), "--workers", "2", "--seed", "4", *SHORT]
    assert main(["batch", str(src), "-o", str(tmp_path / "pool"), *common]) == 0
    assert main(["batch", str(src), "-o", str(tmp_path / "dask"), "--dask", *common]) == 0
    folders = _result_folders(tmp_path / "pool")
    assert len(folders) == 3 and folders == _result_folders(tmp_path / "dask")
    for rel in folders:
        a, b = (json.loads((tmp_path / eng / rel / "summary.json").read_text())
                for eng in ("pool", "dask"))
        assert _comparable(a) == _comparable(b)
        with np.load(tmp_path / "pool" / rel / "posterior.npz") as za, \
                np.load(tmp_path / "dask" / rel / "posterior.npz") as zb:
            assert sorted(za.files) == sorted(zb.files)
            for k in za.files:
                np.testing.assert_array_equal(za[k], zb[k])
