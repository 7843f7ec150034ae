"""Finding a batch's images and landmarks, and planning which images to fit (no fits)."""

from __future__ import annotations

import os
from pathlib import Path, PurePosixPath

import pytest

from mcmcfit.batch.discovery import discover, list_images
from mcmcfit.batch.run import BatchOptions, plan_batch
from mcmcfit.batch.seeds import image_seed
from mcmcfit.fitting.config import FitConfig


def _touch(path: Path, text: str = "x") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.fixture
def tree(tmp_path):
    root = tmp_path / "lfw"
    for rel in ("Ann/Ann_0001.jpg", "Ann/Ann_0002.JPG", "Bob/Bob_0001.png", "Bob/deep/Bob_9.jpeg",
                "top.png", "Ann/notes.txt", ".hidden/x.png", "Bob/.x.png"):
        _touch(root / rel)
    _touch(root / "Ann/Ann_0001.tlms")
    _touch(root / "Bob/Bob_0001.pts")
    _touch(root / "Bob/Bob_0001.tlms")  # .tlms wins over .pts
    return root


def test_folder_is_walked_recursively_for_images_only(tree):
    found = [s for _, s in list_images(tree)]
    assert found == ["Ann/Ann_0001.jpg", "Ann/Ann_0002.JPG", "Bob/Bob_0001.png",
                     "Bob/deep/Bob_9.jpeg", "top.png"]
    assert all(p.is_absolute() and p.is_file() for p, _ in list_images(tree))


def test_output_folder_inside_input_is_not_walked(tree):
    _touch(tree / "results" / "Ann" / "Ann_0001" / "fit.png")
    found = [s for _, s in list_images(tree, exclude=[tree / "results"])]
    assert not any(s.startswith("results/") for s in found)


def test_landmarks_beside_images_and_skip_reasons(tree):
    items, skipped = discover(tree)
    by = {i.source: i for i in items}
    assert set(by) == {"Ann/Ann_0001.jpg", "Bob/Bob_0001.png"}
    assert by["Ann/Ann_0001.jpg"].landmarks == tree / "Ann/Ann_0001.tlms"
    assert by["Bob/Bob_0001.png"].landmarks == tree / "Bob/Bob_0001.tlms"
    assert by["Bob/Bob_0001.png"].relative == PurePosixPath("Bob/Bob_0001")
    reasons = {s.source: s.reason for s in skipped}
    assert set(reasons) == {"Ann/Ann_0002.JPG", "Bob/deep/Bob_9.jpeg", "top.png"}
    assert "no landmark file" in reasons["top.png"] and "--face-box-default" in reasons["top.png"]


def test_face_box_default_keeps_images_without_landmarks(tree):
    items, skipped = discover(tree, allow_face_box=True)
    assert len(items) == 5 and not skipped
    assert {i.source for i in items if i.landmarks is None} == \
        {"Ann/Ann_0002.JPG", "Bob/deep/Bob_9.jpeg", "top.png"}


def test_landmarks_dir_is_a_parallel_tree(tree, tmp_path):
    lms = tmp_path / "lms"
    _touch(lms / "Ann/Ann_0002.pts")
    _touch(lms / "Bob/deep/Bob_9.tlms")
    items, skipped = discover(tree, landmarks_dir=lms)
    assert {i.source: i.landmarks for i in items} == {
        "Ann/Ann_0002.JPG": lms / "Ann/Ann_0002.pts",
        "Bob/deep/Bob_9.jpeg": lms / "Bob/deep/Bob_9.tlms"}
    assert len(skipped) == 3  # the files beside the images are not used with --landmarks-dir


def test_landmarks_glob_pattern_and_ambiguity(tree, tmp_path):
    _touch(tmp_path / "marks" / "Ann" / "Ann_0002_det.pts")
    _touch(tmp_path / "marks" / "top_a.pts")
    _touch(tmp_path / "marks" / "top_b.pts")
    pattern = str(tmp_path / "marks" / "{parent}" / "{stem}*.pts")
    items, skipped = discover(tree, landmarks_glob=pattern, allow_face_box=True)
    by = {i.source: i.landmarks for i in items}
    assert by["Ann/Ann_0002.JPG"] == tmp_path / "marks/Ann/Ann_0002_det.pts"
    assert by["Bob/Bob_0001.png"] is None  # no match: face box
    assert [s.source for s in skipped] == ["top.png"]  # two matches: never guessed
    assert "matches 2 files" in skipped[0].reason
    # relative patterns are relative to the image's folder
    items, _ = discover(tree, landmarks_glob="{stem}.tlms")
    assert {i.source for i in items} == {"Ann/Ann_0001.jpg", "Bob/Bob_0001.png"}


def test_list_file_entries_and_escaping_names(tmp_path):
    base = tmp_path / "lists" / "sub"
    img = _touch(tmp_path / "etc" / "x.jpg")
    _touch(img.with_suffix(".tlms"))
    local = _touch(base / "Ann" / "Ann_0001.png")
    _touch(local.with_suffix(".tlms"))
    absolute = _touch(tmp_path / "elsewhere" / "y.png")
    _touch(absolute.with_suffix(".tlms"))
    lst = _touch(base / "images.txt", "# comment\n\n../../etc/x.jpg\nAnn/Ann_0001.png\n"
                 f"{absolute}\n{local}\n")
    items, skipped = discover(lst)
    assert [(i.source, str(i.relative)) for i in items] == [
        ("../../etc/x.jpg", "_up/_up/etc/x"), ("Ann/Ann_0001.png", "Ann/Ann_0001"),
        (str(absolute), "_abs" + os.path.splitext(str(absolute))[0])]
    assert items[0].image == img and items[0].landmarks == img.with_suffix(".tlms")
    # the absolute path of an image under the list's folder is the same image as its relative line
    assert [s.reason for s in skipped] == ["same output folder as Ann/Ann_0001.png"]


def test_plan_keeps_escaping_outputs_inside_out_and_derives_seeds(tmp_path):
    img = _touch(tmp_path / "etc" / "x.jpg")
    _touch(img.with_suffix(".tlms"))
    lst = _touch(tmp_path / "a" / "b" / "list.txt", "../../etc/x.jpg\n")
    out = tmp_path / "a" / "b" / "OUT"
    plan = plan_batch(BatchOptions(input=lst, out=out, seed=5, config=FitConfig(steps=10)))
    (task,) = plan.tasks
    assert os.path.commonpath([out.absolute(), task.out_dir]) == str(out.absolute())
    assert Path(task.out_dir) == out.absolute() / "_up" / "_up" / "etc" / "x"
    assert task.seed == image_seed(5, "_up/_up/etc/x")
    assert FitConfig.from_dict(task.config).steps == 10


def test_plan_skips_complete_redoes_incomplete_and_force_refits(tree, tmp_path):
    out = tmp_path / "OUT"
    done = out / "Ann" / "Ann_0001"
    done.mkdir(parents=True)
    (done / "summary.json").write_text("{}")
    half = out / "Bob" / "Bob_0001"
    half.mkdir(parents=True)  # no summary.json: incomplete (not written by a fit job)
    plan = plan_batch(BatchOptions(input=tree, out=out))
    assert [i.source for i in plan.complete] == ["Ann/Ann_0001.jpg"]
    assert [(t.source, t.force) for t in plan.tasks] == [("Bob/Bob_0001.png", True)]
    forced = plan_batch(BatchOptions(input=tree, out=out, force=True))
    assert sorted(t.source for t in forced.tasks) == ["Ann/Ann_0001.jpg", "Bob/Bob_0001.png"]
    assert not forced.complete
