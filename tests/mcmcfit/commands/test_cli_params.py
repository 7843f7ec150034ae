"""``mcmcfit params convert``: any .rps version in, V4 out; bad input writes nothing."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from albedo_model.io.rps import format_rps_text, read_rps
from mcmcfit.cli import main


def _strip_types(obj):
    if isinstance(obj, dict):
        return {k: _strip_types(v) for k, v in obj.items() if k != "@type"}
    return obj


def _same_params(a, b):
    for x, y in zip(a, b, strict=True):
        if isinstance(x, tuple) and hasattr(x, "_fields"):
            assert _same_params(x, y)
        elif isinstance(x, np.ndarray):
            assert x.shape == y.shape and x.tobytes() == y.tobytes()
        else:
            assert x == y and type(x) is type(y)
    return True


@pytest.mark.parametrize("version", [1, 2, 3, 4])
def test_convert_writes_v4(shared_data, tmp_path, version, capsys):
    src = shared_data / "scalismo" / f"renderParametersV{version}.rps"
    out = tmp_path / "out.rps"
    assert main(["params", "convert", str(src), "-o", str(out)]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    written = json.loads(out.read_text())
    assert written["version"] == "V4.0"
    assert written.pop("specularExponent") == 20.0
    # every version of the fixture describes the scene of the V4 fixture
    v4 = json.loads((shared_data / "scalismo" / "renderParametersV4.rps").read_text())
    assert _strip_types(written) == v4
    assert _same_params(read_rps(out), read_rps(src))


def test_convert_v1_output_is_the_writer_output(shared_data, tmp_path):
    src = shared_data / "scalismo" / "renderParametersV1.rps"
    out = tmp_path / "v4.rps"
    assert main(["params", "convert", str(src), "-o", str(out)]) == 0
    assert out.read_text() == format_rps_text(read_rps(src))


def test_convert_in_place(shared_data, tmp_path):
    path = tmp_path / "p.rps"
    shutil.copy(shared_data / "scalismo" / "renderParametersV2.rps", path)
    before = read_rps(path)
    assert main(["params", "convert", str(path), "-o", str(path)]) == 0
    assert json.loads(path.read_text())["version"] == "V4.0"
    assert _same_params(read_rps(path), before)


BAD_INPUTS = {
    "unknown_version": '{"version": "V7.0"}',
    "malformed_json": '{"pose": {"scaling": 1.0,',
    "missing_field": None,  # V4 fixture without camera.principalPoint, built in the test
    "not_an_object": "[]",
}


@pytest.mark.parametrize("kind", sorted(BAD_INPUTS))
@pytest.mark.parametrize("existing_output", [False, True])
def test_bad_input_one_stderr_line_and_no_output(shared_data, tmp_path, capsys, kind,
                                                 existing_output):
    src = tmp_path / "in.rps"
    if BAD_INPUTS[kind] is None:
        data = json.loads((shared_data / "scalismo" / "renderParametersV4.rps").read_text())
        del data["camera"]["principalPoint"]
        src.write_text(json.dumps(data))
    else:
        src.write_text(BAD_INPUTS[kind])
    out = tmp_path / "out.rps"
    if existing_output:
        out.write_text("old output")
    code = main(["params", "convert", str(src), "-o", str(out)])
    err = capsys.readouterr().err
    assert code != 0
    assert len(err.strip().splitlines()) == 1 and str(src) in err
    if existing_output:
        assert out.read_text() == "old output"
    else:
        assert not out.exists()
    expected = {"in.rps", "out.rps"} if existing_output else {"in.rps"}
    assert {p.name for p in tmp_path.iterdir()} == expected  # no temporary left behind


def test_missing_input_file(tmp_path, capsys):
    out = tmp_path / "out.rps"
    assert main(["params", "convert", str(tmp_path / "nope.rps"), "-o", str(out)]) != 0
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "nope.rps" in err
    assert not out.exists()


def test_process_exit_code_and_stderr(tmp_path):
    src = tmp_path / "bad.rps"
    src.write_text('{"version": "V5.0"}')
    out = tmp_path / "out.rps"
    proc = subprocess.run([sys.executable, "-m", "mcmcfit", "params", "convert", str(src),
                           "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode != 0
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "V5.0" in lines[0] and str(src) in lines[0]
    assert proc.stdout == "" and not out.exists()
