"""TLMS (2D/3D) and iBUG ``.pts`` landmark files."""

from __future__ import annotations

import numpy as np
import pytest

from albedo_model.errors import FormatError, InputError
from albedo_model.io.pts import IBUG68_TO_BASEL, parse_pts_text, pts_to_landmarks, read_pts
from albedo_model.io.tlms import (
    Landmark,
    format_tlms_text,
    landmarks_to_dict,
    parse_tlms_text,
    read_tlms,
    write_tlms,
)

AWKWARD = [0.1, -0.0, 1e-300, 5e-324, 1.7976931348623157e308, 123456.789012345678, -2.5,
           1 / 3]


# -- TLMS ----------------------------------------------------------------------

@pytest.mark.parametrize("dim", [2, 3])
def test_tlms_round_trip_is_exact_with_visibility(tmp_path, dim):
    rng = np.random.default_rng(dim)
    values = np.concatenate([AWKWARD, rng.normal(size=40) * 10.0 ** rng.integers(-8, 8, 40)])
    points = values[: (len(values) // dim) * dim].reshape(-1, dim)
    lms = [Landmark(f"lm.{i}", tuple(float(v) for v in p), bool(i % 3))
           for i, p in enumerate(points)]
    write_tlms(tmp_path / "a.tlms", lms)
    back = read_tlms(tmp_path / "a.tlms")
    assert back == lms
    for a, b in zip(back, lms, strict=True):  # bit-exact, including the sign of zero
        assert np.array(a.point).tobytes() == np.array(b.point).tobytes()
    assert [lm.visible for lm in back] == [bool(i % 3) for i in range(len(lms))]


def test_tlms_line_format():
    text = format_tlms_text([Landmark("left.eye.corner_outer", (0.1, 2.0), False),
                             Landmark("center.nose.tip", (1.5, -3.25), True)])
    assert text == ("left.eye.corner_outer 0 0.10000000000000001 2\n"
                    "center.nose.tip 1 1.5 -3.25\n")


def test_tlms_reads_scalismo_written_lines():
    # Java's %.17g pads with zeros; extra spaces and blank lines are allowed
    text = ("\nright.eye.corner_outer 1 120.50000000000000 87.250000000000000\n"
            "  left.lips.corner\t0   3.0000000000000000   -1.0000000000000000e-05  \n\n")
    lms = parse_tlms_text(text)
    assert lms == [Landmark("right.eye.corner_outer", (120.5, 87.25), True),
                   Landmark("left.lips.corner", (3.0, -1e-05), False)]
    assert all(lm.dim == 2 for lm in lms)


def test_tlms_visibility_is_positive_flag():
    lms = parse_tlms_text("a 2 0 0\nb -1 0 0\nc 0 0 0\n")
    assert [lm.visible for lm in lms] == [True, False, False]


def test_tlms_text_embedded_in_scalismo_model(shared_data):
    h5py = pytest.importorskip("h5py")
    with h5py.File(shared_data / "scalismo" / "random-l4.h5", "r") as f:
        text = f["/metadata/landmarks/text"][()].decode()
    lms = parse_tlms_text(text, dim=3, source="random-l4.h5")
    named = landmarks_to_dict(lms)
    assert len(lms) == len(named) > 50 and all(lm.dim == 3 for lm in lms)
    np.testing.assert_array_equal(named["center.nose.tip"], [0.203733876, 0.97169292, 131.823807])
    # "left" is the subject's left: +x in the model frame (the face looks along +z)
    assert named["left.eye.corner_outer"][0] > 30 and named["right.eye.corner_outer"][0] < -30


@pytest.mark.parametrize("text,dim,reason", [
    ("a 1 2\n", None, "line 1: expected 4 fields"),
    ("a 1 2 3 4 5\n", None, "line 1: expected 4 fields"),
    ("a 1 2 3\nb 1 2 3 4\n", None, "line 2: expected 4 fields (name visible x y) for 2D"),
    ("a 1 2 3 4\n\nb 1 2 3\n", None, "line 3: expected 5 fields"),
    ("a 1 2 3\n", 3, "line 1: expected 5 fields"),
    ("a 1 x 3\n", None, "line 1: coordinate 'x' is not a number"),
    ("a yes 1 3\n", None, "line 1: visibility flag 'yes' is not a number"),
    ("a 1 nan 3\n", None, "line 1: coordinate 'nan' is not finite"),
])
def test_tlms_malformed_lines(tmp_path, text, dim, reason):
    path = tmp_path / "bad.tlms"
    path.write_text(text)
    with pytest.raises(FormatError) as info:
        read_tlms(path, dim=dim)
    assert str(path) in str(info.value) and reason in str(info.value)


def test_tlms_not_text(tmp_path):
    path = tmp_path / "bin.tlms"
    path.write_bytes(b"\xff\xfe\xfa")
    with pytest.raises(FormatError, match="not UTF-8"):
        read_tlms(path)


@pytest.mark.parametrize("lms,reason", [
    ([Landmark("has space", (1.0, 2.0))], "whitespace"),
    ([Landmark("a", (1.0, 2.0)), Landmark("b", (1.0, 2.0, 3.0))], "mix dimensions"),
    ([Landmark("a", (1.0, float("inf")))], "non-finite"),
    ([Landmark("a", (1.0,))], "2D or 3D"),
])
def test_tlms_write_rejects_bad_landmarks_without_writing(tmp_path, lms, reason):
    path = tmp_path / "out.tlms"
    with pytest.raises(InputError, match=reason):
        write_tlms(path, lms)
    assert not path.exists() and list(tmp_path.iterdir()) == []


def test_landmarks_to_dict():
    lms = [Landmark("a", (1.0, 2.0), True), Landmark("b", (3.0, 4.0), False)]
    assert list(landmarks_to_dict(lms, visible_only=True)) == ["a"]
    with pytest.raises(InputError, match="twice"):
        landmarks_to_dict(lms + [Landmark("a", (0.0, 0.0))])


# -- iBUG .pts -----------------------------------------------------------------

def synthetic_frontal_ibug(cx=200.0):
    """68 points laid out per the iBUG numbering, image x right / y down, frontal face.

    Built group by group from the published scheme: jaw 1-17 from the image left
    (subject's right) to the image right; brows 18-22 and 23-27 left to right;
    nose bridge 28-31 top to tip; nostrils 32-36 left to right; eyes 37-42
    (subject's right, starting at its outer corner, clockwise) and 43-48 (starting
    at the inner corner); outer lips 49-60 from the image-left corner clockwise;
    inner lips 61-68 likewise.
    """
    p = np.zeros((68, 2))
    t = np.linspace(-1, 1, 17)
    p[0:17] = np.c_[cx + 90 * t, 200 + 110 * np.sqrt(1 - t**2)]  # chin (row 8) lowest
    p[17:22] = np.c_[cx - np.linspace(75, 15, 5), [140, 132, 130, 132, 136]]
    p[22:27] = np.c_[cx + np.linspace(15, 75, 5), [136, 132, 130, 132, 140]]
    p[27:31] = np.c_[[cx] * 4, np.linspace(160, 220, 4)]
    p[31:36] = np.c_[cx + np.linspace(-20, 20, 5), [232, 236, 238, 236, 232]]
    eye = np.array([[-20, 0], [-10, -6], [10, -6], [20, 0], [10, 5], [-10, 5]], float)
    p[36:42] = eye + [cx - 40, 165]  # starts at its outer (image-left) corner
    p[42:48] = eye + [cx + 40, 165]  # starts at its inner corner
    ang = np.linspace(np.pi, -np.pi, 13)[:-1]
    p[48:60] = np.c_[cx + 35 * np.cos(ang), 270 - 14 * np.sin(ang)]
    ang = np.linspace(np.pi, -np.pi, 9)[:-1]
    p[60:68] = np.c_[cx + 25 * np.cos(ang), 270 - 4 * np.sin(ang)]
    return p


def pts_text(points, one_based=True):
    body = "\n".join(f"{float(x) + one_based!r} {float(y) + one_based!r}" for x, y in points)
    return f"version: 1\nn_points:  {len(points)}\n{{\n{body}\n}}\n"


def test_read_pts_subtracts_one(tmp_path):
    pts = synthetic_frontal_ibug()
    path = tmp_path / "face.pts"
    path.write_text(pts_text(pts, one_based=True))
    got = read_pts(path)
    assert got.shape == (68, 2) and got.dtype == np.float64
    np.testing.assert_allclose(got, pts, rtol=0, atol=1e-12)
    np.testing.assert_allclose(read_pts(path, one_based=False), pts + 1, rtol=0, atol=1e-12)


def test_pts_generic_count_and_crlf():
    text = "version: 1\r\nn_points: 3\r\n{\r\n1 2\r\n3 4\r\n5.5 6\r\n}\r\n"
    np.testing.assert_array_equal(parse_pts_text(text, n_points=None),
                                  [[0, 1], [2, 3], [4.5, 5]])


@pytest.mark.parametrize("text,reason", [
    ("version: 1\nn_points: 68\n1 2\n", "no '{'"),
    ("version: 1\n{\n1 2\n}\n", "missing 'n_points:'"),
    ("version: 1\nn_points: 68\n{\n1 2\n", "no '}'"),
    ("version: 1\nn_points: 2\n{\n1 2\n3 4\n5 6\n}\n", "header says 2 points, the list has 3"),
    ("version: 1\nn_points: 2\n{\n1 2\n3 4\n}\n", "expected 68 points"),
    ("version: 1\nn_points: 1\n{\n1 b\n}\n", "line 4: coordinate 'b'"),
    ("version: 1\nn_points: 1\n{\n1 2 3\n}\n", "line 4: expected 2 coordinates"),
])
def test_pts_malformed(tmp_path, text, reason):
    path = tmp_path / "bad.pts"
    path.write_text(text)
    n = None if "n_points: 1\n" in text else 68
    with pytest.raises(FormatError) as info:
        read_pts(path, n_points=n)
    assert str(path) in str(info.value) and reason in str(info.value)


def test_ibug_mapping_documented_points():
    # iBUG numbers are 1-based; the mapping is keyed by 0-based rows
    assert IBUG68_TO_BASEL[37 - 1] == "right.eye.corner_outer"
    assert IBUG68_TO_BASEL[40 - 1] == "right.eye.corner_inner"
    assert IBUG68_TO_BASEL[43 - 1] == "left.eye.corner_inner"
    assert IBUG68_TO_BASEL[46 - 1] == "left.eye.corner_outer"
    assert IBUG68_TO_BASEL[9 - 1] == "center.chin.tip"
    assert IBUG68_TO_BASEL[31 - 1] == "center.nose.tip"
    assert IBUG68_TO_BASEL[49 - 1] == "right.lips.corner"
    assert IBUG68_TO_BASEL[55 - 1] == "left.lips.corner"
    assert len(set(IBUG68_TO_BASEL.values())) == len(IBUG68_TO_BASEL)


def test_ibug_mapping_names_are_basel_names(shared_data):
    h5py = pytest.importorskip("h5py")
    with h5py.File(shared_data / "scalismo" / "random-l4.h5", "r") as f:
        names = {lm.name for lm in parse_tlms_text(f["/metadata/landmarks/text"][()].decode())}
    assert set(IBUG68_TO_BASEL.values()) <= names


def test_pts_to_landmarks_sides_and_order(tmp_path):
    cx = 200.0
    path = tmp_path / "face.pts"
    path.write_text(pts_text(synthetic_frontal_ibug(cx)))
    lms = pts_to_landmarks(read_pts(path))
    assert len(lms) == len(IBUG68_TO_BASEL) and all(lm.dim == 2 and lm.visible for lm in lms)
    d = landmarks_to_dict(lms)
    for name, (x, _) in d.items():
        side = name.split(".")[0]
        # frontal photo: the subject's right appears on the image's left
        if side == "right":
            assert x < cx - 5, name
        elif side == "left":
            assert x > cx + 5, name
        else:
            assert abs(x - cx) < 1e-6, name
    y = {k: v[1] for k, v in d.items()}
    assert y["left.eyebrow.inner_upper"] < y["left.eye.corner_inner"] < y["center.nose.tip"] \
        < y["center.lips.upper.outer"] < y["center.lips.lower.outer"] < y["center.chin.tip"]
    for side in ("left", "right"):  # outer eye corners are farther from the midline
        assert abs(d[f"{side}.eye.corner_outer"][0] - cx) > abs(d[f"{side}.eye.corner_inner"][0]
                                                                - cx)


def test_pts_to_landmarks_shape_check():
    with pytest.raises(InputError):
        pts_to_landmarks(np.zeros((5, 2)))
