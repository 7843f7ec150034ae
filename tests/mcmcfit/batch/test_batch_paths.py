"""Batch plumbing without fits: safe output paths, seeds, the LFW face box, journals."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path, PurePosixPath

import pytest

from mcmcfit.batch.face_boxes import LFW_ENLARGEMENT, lfw_face_box
from mcmcfit.batch.journal import append_line, read_journal
from mcmcfit.batch.out_paths import (
    is_complete,
    remove_stale_temp_dirs,
    result_dir,
    safe_relative,
    stale_temp_dirs,
)
from mcmcfit.batch.seeds import image_seed


def _inside(root: Path, path: Path) -> bool:
    root, path = os.path.realpath(root), os.path.realpath(path)
    return os.path.commonpath([root, path]) == root and path != root


@pytest.mark.parametrize("name", [
    "../../etc/x.jpg", "..\\..\\etc\\x.jpg", "/etc/x.jpg", "a/../../b.png", "./../.x.png",
    "C:\\Windows\\x.png", "a/./b/../../../c.jpeg", "..", "...", "a/..",
])
def test_output_paths_of_hostile_names_stay_inside_out(tmp_path, name):
    out = tmp_path / "OUT"
    out.mkdir()
    try:
        rel = safe_relative(name)
    except ValueError:  # nothing usable: refused, which is also safe
        assert name in ("..", "a/..")
        return
    folder = result_dir(out, rel)
    assert _inside(out, folder), (name, folder)
    assert ".." not in rel.parts and not rel.is_absolute()
    folder.mkdir(parents=True)  # creating it really creates it under OUT
    assert _inside(out, folder.resolve())


def test_safe_relative_keeps_ordinary_paths_and_drops_the_extension():
    assert safe_relative("George_W_Bush/George_W_Bush_0001.jpg") == \
        PurePosixPath("George_W_Bush/George_W_Bush_0001")
    assert safe_relative("../../etc/x.jpg") == PurePosixPath("_up/_up/etc/x")
    assert safe_relative("/etc/x.jpg") == PurePosixPath("_abs/etc/x")
    # distinct inputs stay distinct
    assert safe_relative("../x.jpg") != safe_relative("x.jpg")


def test_result_dir_refuses_unsafe_relative_paths(tmp_path):
    for bad in ("../x", "/abs/x", "a/../../x"):
        with pytest.raises(ValueError):
            result_dir(tmp_path, PurePosixPath(bad))


def test_complete_folder_and_stale_temporaries(tmp_path):
    folder = tmp_path / "Ann" / "Ann_0001"
    assert not is_complete(folder)
    folder.mkdir(parents=True)
    assert not is_complete(folder)  # an incomplete folder (no summary.json)
    (folder / "summary.json").write_text("{}")
    assert is_complete(folder)
    stale = [tmp_path / "Ann" / ".Ann_0001.partial-abc", tmp_path / "Ann" / ".Ann_0001.old-x"]
    other = tmp_path / "Ann" / ".Ann_0002.partial-abc"  # another image's: left alone
    for d in stale + [other]:
        d.mkdir()
    assert stale_temp_dirs(folder) == sorted(stale)
    remove_stale_temp_dirs(folder)
    assert not any(d.exists() for d in stale) and other.exists() and is_complete(folder)


def test_image_seed_depends_only_on_root_seed_and_path():
    a = image_seed(7, "Ann/Ann_0001")
    assert a == image_seed(7, PurePosixPath("Ann/Ann_0001"))
    assert 0 <= a < 2 ** 63
    seeds = {image_seed(7, f"S{i}/S{i}_0001") for i in range(200)}
    assert len(seeds) == 200  # no collisions among distinct paths
    assert image_seed(8, "Ann/Ann_0001") != a
    # the same in a fresh interpreter (no hash randomisation involved)
    code = "from mcmcfit.batch.seeds import image_seed; print(image_seed(7, 'Ann/Ann_0001'))"
    fresh = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                           env={**os.environ, "PYTHONHASHSEED": "123"}, check=True)
    assert int(fresh.stdout) == a


def test_lfw_face_box_is_the_detected_square_before_the_enlargement():
    x0, y0, x1, y1 = lfw_face_box(250, 250)
    side = 250 / LFW_ENLARGEMENT
    assert x1 - x0 == pytest.approx(side) and y1 - y0 == pytest.approx(side)
    assert (x0 + x1) / 2 == pytest.approx(125) and (y0 + y1) / 2 == pytest.approx(125)
    assert lfw_face_box(500, 500) == pytest.approx(tuple(2 * v for v in (x0, y0, x1, y1)))


def test_journal_lines_survive_a_truncated_last_line(tmp_path):
    path = tmp_path / "batch.jsonl"
    append_line(path, {"path": "a.png", "x": 1.5, "nan": float("nan")})
    append_line(path, {"path": "b.png", "x": 2})
    # a writer killed mid-line leaves half a record without a newline
    with open(path, "ab") as fh:
        fh.write(b'{"path": "c.png", "x"')
    records = read_journal(path)
    assert [r["path"] for r in records] == ["a.png", "b.png"]
    assert records[0]["nan"] is None
    # the next append starts on a line of its own, so nothing after the damage is lost
    append_line(path, {"path": "d.png"})
    assert [r["path"] for r in read_journal(path)] == ["a.png", "b.png", "d.png"]
    lines = path.read_bytes().split(b"\n")
    assert lines[-1] == b"" and json.loads(lines[-2]) == {"path": "d.png"}
    assert read_journal(tmp_path / "missing.jsonl") == []
