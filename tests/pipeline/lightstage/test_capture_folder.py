"""Capture-folder layout: lightstage.json, template.npz, subject folders, masks, spectra CSV."""

import json

import numpy as np
import pytest

from albedo_model.errors import FormatError, InputError
from pipeline.lightstage.colour import camera_colour, camera_colour_from_spectra, spectral_grid
from pipeline.lightstage.capture_folder import (
    LightstageSpec,
    list_subjects,
    read_lightstage,
    read_template,
    read_vertex_mask,
    write_lightstage,
    write_template,
)
from pipeline.lightstage.spectral_csv import read_spectral_csv


def _spec(**kw):
    args = {"camera": {"name": "Nikon 5100 (NPL)"}, "illuminant": {"name": "LED-B4"},
                "raw_to_xyz": "training", "leds_mm": np.array([[0.0, 900.0, 0.0], [900.0, 0, 0]]),
                "led_intensity": np.ones(2), "centre_mm": np.array([0.0, 0.0, 880.0]), "exposure": 0.004}
    args.update(kw)
    return LightstageSpec(**args)


def test_lightstage_json_round_trip(tmp_path):
    write_lightstage(tmp_path, _spec(shading="flat", specular_exponent=12.0))
    spec = read_lightstage(tmp_path)
    assert np.allclose(spec.leds_mm, [[0, 900, 0], [900, 0, 0]])
    assert spec.shading == "flat" and spec.specular_exponent == 12.0
    assert spec.exposure == 0.004 and spec.polariser_transmission == 0.5
    assert np.allclose(spec.colour().matrix, camera_colour().matrix)


@pytest.mark.parametrize("change, message", [
    ({"format": "other"}, "format"),
    ({"leds_mm": [[1, 2]]}, "leds_mm"),
    ({"shading": "uniform"}, "shading"),
    ({"exposure": -1}, "positive"),
    ({"camera": {"name": 3}}, "camera"),
])
def test_bad_lightstage_json_names_the_file(tmp_path, change, message):
    data = {**_spec().to_json(), **change}
    (tmp_path / "lightstage.json").write_text(json.dumps(data))
    with pytest.raises(FormatError, match=message) as err:
        read_lightstage(tmp_path)
    assert "lightstage.json" in str(err.value)


def test_missing_lightstage_json(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_lightstage(tmp_path)


def test_template_round_trip_and_checks(tmp_path, stand_in_head):
    write_template(tmp_path, stand_in_head)
    t = read_template(tmp_path)
    assert np.array_equal(t.triangles, stand_in_head.triangles)
    assert np.array_equal(t.symmetry, stand_in_head.symmetry)
    assert np.array_equal(t.eyeballs, stand_in_head.regions["eyeballs"])
    assert t.landmarks == stand_in_head.landmarks
    bad = dict(np.load(tmp_path / "template.npz"))
    bad["symmetry"] = np.zeros_like(bad["symmetry"])
    np.savez(tmp_path / "template.npz", **bad)
    with pytest.raises(FormatError, match="involution"):
        read_template(tmp_path)


def test_subject_listing_and_mask(tmp_path):
    folder = tmp_path / "subjects" / "anna"
    folder.mkdir(parents=True)
    (tmp_path / "subjects" / "incomplete").mkdir()          # no subject.json: skipped
    (folder / "subject.json").write_text(json.dumps({
        "iso": 400, "views": [{"name": "frontal", "parallel": "a.tif", "perpendicular": "b.tif"}],
        "mask": "mask.txt"}))
    (folder / "mask.txt").write_text("# artefacts\n3\n5  # hair\n\n")
    entries = list_subjects(tmp_path)
    assert [e.subject_id for e in entries] == ["anna"]
    e = entries[0]
    assert e.iso == 400 and e.parallel == (folder / "a.tif",) and e.truth is None
    mask = read_vertex_mask(e.mask, 8)
    assert np.flatnonzero(mask).tolist() == [3, 5]
    (folder / "mask.txt").write_text("9\n")
    with pytest.raises(FormatError, match="mask.txt"):
        read_vertex_mask(e.mask, 8)
    (folder / "subject.json").write_text(json.dumps({"views": []}))
    with pytest.raises(FormatError, match="views"):
        list_subjects(tmp_path)


def test_spectral_csv_in_the_jiang_format(tmp_path):
    wl = np.arange(400, 721, 10)
    sens = np.stack([np.exp(-0.5 * ((wl - mu) / 40.0) ** 2) for mu in (600, 540, 460)], axis=1)
    lines = ["# Nikon D200-like test camera", "# wavelength,R,G,B"]
    lines += [f"{w},{r:.6f},{g:.6f},{b:.6f}" for w, (r, g, b) in zip(wl, sens)]
    path = tmp_path / "camera.csv"
    path.write_text("\n".join(lines) + "\n")
    table = read_spectral_csv(path, 3)
    grid = spectral_grid()
    assert table.shape == (len(grid), 3)
    assert np.allclose(table, sens[: len(grid)], atol=1e-6)   # same 10 nm samples
    colour = camera_colour_from_spectra(table, camera_colour().illuminant, camera="csv",
                                        illuminant_name="LED-B4")
    white = colour.sensitivities.T @ colour.illuminant
    assert np.allclose(colour.matrix @ white, 1.0)
    short = tmp_path / "short.csv"
    short.write_text("\n".join(f"{w},1,1,1" for w in range(450, 700, 10)))
    with pytest.raises(FormatError, match="covers"):
        read_spectral_csv(short, 3)
    broken = tmp_path / "broken.csv"
    broken.write_text("400,1,1\n410,1,1\n")
    with pytest.raises(FormatError, match="expected 4 values"):
        read_spectral_csv(broken, 3)
