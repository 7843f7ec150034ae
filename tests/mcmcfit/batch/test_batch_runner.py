"""Batch runners and journals with stand-in tasks (no fits).

Spawned workers, thread limits, worker loss, Dask LocalCluster, one journal line
per outcome, resume.
"""

from __future__ import annotations

import os
from pathlib import Path

import batch_fake_tasks as fake
import pytest

from mcmcfit.batch.journal import read_journal
from mcmcfit.batch.pool_runner import pool_outcomes
from mcmcfit.batch.run import BatchOptions, run_batch
from mcmcfit.batch.task import FitTask


def _tasks(tmp_path: Path, n: int) -> list[FitTask]:
    return [FitTask(image=str(tmp_path / f"i{k}.png"), source=f"S/i{k}.png", relative=f"S/i{k}",
                    out_dir=str(tmp_path / "OUT" / "S" / f"i{k}"), landmarks=None, face_box=None,
                    model="default", config={}, seed=k) for k in range(n)]


def test_pool_workers_are_spawned_with_thread_limits(tmp_path):
    outs = list(pool_outcomes(_tasks(tmp_path, 4), workers=2, threads=1, fn=fake.describe_worker))
    assert sorted(o["path"] for o in outs) == [f"S/i{k}.png" for k in range(4)]
    assert all(o["pid"] != os.getpid() for o in outs)
    assert len({o["pid"] for o in outs}) <= 2
    for o in outs:
        assert o["env"]["OMP_NUM_THREADS"] == "1" and o["env"]["OPENBLAS_NUM_THREADS"] == "1"
        assert o["env"]["MKL_NUM_THREADS"] == "1"
        assert "xla_cpu_multi_thread_eigen=false" in o["env"]["XLA_FLAGS"]
        assert not o["jax_loaded"]  # spawned: nothing imported JAX before the limits were set


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this OS")
def test_pinned_workers_run_on_one_core_each(tmp_path):
    outs = list(pool_outcomes(_tasks(tmp_path, 2), workers=2, pin=True, fn=fake.describe_worker))
    assert all(len(o["affinity"]) == 1 for o in outs)
    allowed = sorted(os.sched_getaffinity(0))
    assert all(o["affinity"][0] in allowed for o in outs)


def test_pool_retries_images_whose_worker_died(tmp_path):
    outs = list(pool_outcomes(_tasks(tmp_path, 3), workers=2, fn=fake.die_once))
    assert sorted(o["path"] for o in outs) == ["S/i0.png", "S/i1.png", "S/i2.png"]
    assert all(o["status"] == "ok" for o in outs)


def test_pool_reports_images_whose_worker_always_dies(tmp_path):
    outs = list(pool_outcomes(_tasks(tmp_path, 2), workers=1, retries=1, fn=fake.die_always))
    assert len(outs) == 2 and all(o["status"] == "failed" for o in outs)
    assert all("worker process died" in o["reason"] for o in outs)


def test_a_worker_killing_image_fails_alone_and_bystanders_are_fitted(tmp_path):
    outs = list(pool_outcomes(_tasks(tmp_path, 5), workers=2, retries=1, fn=fake.die_for_i1))
    status = {o["path"]: o["status"] for o in outs}
    assert len(outs) == 5 and status.pop("S/i1.png") == "failed"
    assert set(status.values()) == {"ok"}


def test_pool_reports_a_raising_task_and_goes_on(tmp_path):
    outs = list(pool_outcomes(_tasks(tmp_path, 2), workers=1, fn=fake.raise_error))
    assert [o["status"] for o in outs] == ["failed", "failed"]
    assert all("unexpected failure" in o["reason"] for o in outs)


def test_dask_local_cluster_runs_every_task_with_thread_limits(tmp_path):
    pytest.importorskip("distributed")
    from mcmcfit.batch.dask_runner import dask_outcomes

    outs = list(dask_outcomes(_tasks(tmp_path, 3), workers=2, threads=1,
                              fn=fake.describe_worker))
    assert sorted(o["path"] for o in outs) == ["S/i0.png", "S/i1.png", "S/i2.png"]
    assert all(o["env"]["OMP_NUM_THREADS"] == "1" and o["pid"] != os.getpid() for o in outs)
    errs = list(dask_outcomes(_tasks(tmp_path, 1), workers=1, retries=0, fn=fake.raise_error))
    assert errs[0]["status"] == "failed" and "unexpected failure" in errs[0]["reason"]


def test_dask_scheduler_address_and_worker_loss(tmp_path):
    pytest.importorskip("distributed")
    from distributed import LocalCluster

    from mcmcfit.batch.dask_runner import dask_outcomes

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        # a worker dies on each image's first try: the scheduler runs the task again
        outs = list(dask_outcomes(_tasks(tmp_path, 2), scheduler=cluster.scheduler_address,
                                  fn=fake.die_once))
        assert sorted(o["path"] for o in outs) == ["S/i0.png", "S/i1.png"]
        assert all(o["status"] == "ok" for o in outs)
        assert all(Path(t.out_dir + ".died").exists() for t in _tasks(tmp_path, 2))


def _tree(root: Path, names: list[str]) -> Path:
    for n in names:
        p = root / n
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(b"png")
        p.with_suffix(".tlms").write_text("x 1 1 1\n")
    return root


def test_run_batch_journals_outcomes_and_resumes(tmp_path):
    src = _tree(tmp_path / "in", ["A/A_0001.png", "A/A_0002.png", "B/bad_0001.png", "B/B_0001.png"])
    (src / "C").mkdir()
    (src / "C" / "C_0001.png").write_bytes(b"png")  # no landmarks: skipped
    out = tmp_path / "OUT"
    opts = BatchOptions(input=src, out=out, workers=2, progress=False)
    first = run_batch(opts, task_fn=fake.write_folder, log=lambda s: None)
    assert (first.fitted, len(first.failed), first.skipped, first.exit_code) == (3, 1, 1, 1)
    ok = read_journal(out / "batch.jsonl")
    assert sorted(r["relative"] for r in ok) == ["A/A_0001", "A/A_0002", "B/B_0001"]
    fails = read_journal(out / "failures.jsonl")
    assert {(r["path"], r["status"]) for r in fails} == {("B/bad_0001.png", "failed"),
                                                       ("C/C_0001.png", "skipped")}
    # a folder completed by a run killed before its journal line, and a truncated last line
    lost = out / "C" / "C_0002"
    lost.mkdir(parents=True)
    (lost / "summary.json").write_text("{}")
    (src / "C" / "C_0002.png").write_bytes(b"png")
    (src / "C" / "C_0002.tlms").write_text("x 1 1 1\n")
    with open(out / "batch.jsonl", "ab") as fh:
        fh.write(b'{"relative": "A/A_00')
    second = run_batch(opts, task_fn=fake.write_folder, log=lambda s: None)
    assert (second.already_complete, second.fitted, len(second.failed)) == (4, 0, 1)
    ok = read_journal(out / "batch.jsonl")
    assert sorted(r["relative"] for r in ok) == ["A/A_0001", "A/A_0002", "B/B_0001", "C/C_0002"]
    assert [r.get("recovered") for r in ok if r["relative"] == "C/C_0002"] == [True]
    # the skipped image is not journaled again with the same reason; the failed one is retried
    fails = read_journal(out / "failures.jsonl")
    assert [r["path"] for r in fails].count("C/C_0001.png") == 1
    assert [r["path"] for r in fails].count("B/bad_0001.png") == 2
