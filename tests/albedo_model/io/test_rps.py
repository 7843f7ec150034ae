"""``.rps`` reading (V1-V4) and V4 writing, against scalismo's fixture files."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest

from albedo_model.errors import FormatError, InputError
from albedo_model.io.rps import (
    format_rps_dict,
    parse_rps_dict,
    parse_rps_text,
    read_rps,
    rps_version,
    write_rps,
)
from albedo_model.params import (
    Camera,
    ColorTransform,
    DirectionalLight,
    ImageSize,
    MoMoCoefficients,
    Pose,
    RenderParameter,
    SHLight,
    View,
    default_square,
)

VERSIONS = ["renderParametersV1.rps", "renderParametersV2.rps", "renderParametersV3.rps",
            "renderParametersV4.rps"]
AMM = ["albedomm-fit-best.rps", "albedomm-fitter-lminit.rps"]

# the V2..V4 fixtures store these SH rows (internal order); V1 stores them permuted
SH_INTERNAL = np.array([[0.5, 0.25, 0.125], [0.125, 0.25, 0.5], [0.25, 0.5, 0.125],
                        [0.5, 0.125, 0.25]])


def assert_identical(a, b, path="params"):
    """Bit-exact equality of parameter records (NamedTuples of floats, tuples, arrays)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, path
        assert a.tobytes() == b.tobytes(), path
    elif isinstance(a, tuple):
        assert type(a) is type(b) and len(a) == len(b), path
        names = getattr(a, "_fields", range(len(a)))
        for name, x, y in zip(names, a, b, strict=True):
            assert_identical(x, y, f"{path}.{name}")
    elif isinstance(a, float):
        assert isinstance(b, float) and (a == b or (math.isnan(a) and math.isnan(b))), path
        assert math.copysign(1, a) == math.copysign(1, b), path
    else:
        assert a == b and type(a) is type(b), path


def load_json(shared_data, name):
    return json.loads((shared_data / "scalismo" / name).read_text())


def without_type_tags(obj):
    if isinstance(obj, dict):
        return {k: without_type_tags(v) for k, v in obj.items() if k != "@type"}
    return obj


# -- fixtures: every field -----------------------------------------------------

@pytest.mark.parametrize("name", VERSIONS)
def test_scalismo_fixture_fields(shared_data, name):
    p = read_rps(shared_data / "scalismo" / name)
    assert p.pose == Pose(1.0, (0.0, 0.0, -1000.0), roll=0.125, yaw=-0.125, pitch=0.25)
    assert p.view == View((10.0, 20.0, 2000.0), roll=-0.125, yaw=1.5, pitch=0.75)
    assert p.image_size == ImageSize(width=720, height=480)
    cam = p.camera
    assert (cam.focal_length, cam.sensor_size, cam.near, cam.far, cam.orthographic) == (
        50.0, (36.0, 24.0), 1.0, 100000.0, False)
    # V1/V2 store (2, -4) pixels: 2*2/720 and 2*(-4)/480 in NDC, no y flip
    assert cam.principal_point == (2 * 2.0 / 720, 2 * -4.0 / 480)
    assert cam.principal_point == (0.005555555555555556, -0.016666666666666666)
    np.testing.assert_array_equal(p.environment_map.coefficients, SH_INTERNAL)
    assert p.directional_light == DirectionalLight()  # "off": SH light present
    assert p.color_transform == ColorTransform((1.0, 0.5, 0.25), 1.0, (0.25, 0.125, 0.75))
    np.testing.assert_array_equal(p.momo.shape, [-1.0, 0.5, -0.25])
    np.testing.assert_array_equal(p.momo.albedo, [1.0, 0.0, 0.5])
    assert p.momo.expression.shape == (0,)
    assert p.momo.model_uri == "modelPath1"
    assert p.specular_exponent == 20.0


def test_all_versions_describe_the_same_scene(shared_data):
    params = [read_rps(shared_data / "scalismo" / n) for n in VERSIONS]
    for p in params[:-1]:
        assert_identical(p, params[-1])


def test_v1_sh_is_stored_in_legacy_order(shared_data):
    raw = load_json(shared_data, "renderParametersV1.rps")["sphericalHarmonicsLight"]
    # legacy order [1, x, y, z, ...]: the internal (1, y, z, x) rows are legacy rows 0, 2, 3, 1
    np.testing.assert_array_equal(np.array(raw)[[0, 2, 3, 1]], SH_INTERNAL)


def test_amm_fit_best(shared_data):
    p = read_rps(shared_data / "scalismo" / "albedomm-fit-best.rps")
    assert p.image_size == ImageSize(250, 250)
    assert p.camera == Camera(134.13737280655158, (2.0, 2.0), 10.0, 1e6,
                              (0.11395619828635972, 0.020775486153173595), False)
    sh = p.environment_map.coefficients
    assert sh.shape == (9, 3) and sh.dtype == np.float64
    np.testing.assert_array_equal(sh[0], [0.3651534407751903, 0.3376333381145733,
                                          0.36495961799525084])
    np.testing.assert_array_equal(sh[8], [-0.19450284471770923, -0.20242904934640313,
                                          -0.20942734640139188])
    assert (p.momo.shape.shape, p.momo.albedo.shape, p.momo.expression.shape) == ((50,), (50,),
                                                                                 (5,))
    assert p.momo.shape[0] == -0.19309327131149293
    assert p.momo.model_uri == ""
    assert p.color_transform.offset == (0.0141877744958488, -0.004362358732503625,
                                        -0.00105158230756267)
    assert p.pose.translation == (-4.384559612266215, -15.241813603569915, -24833.09472154316)
    assert p.view == View()


def test_amm_lminit_is_scalismo_frontal_light(shared_data):
    p = read_rps(shared_data / "scalismo" / "albedomm-fitter-lminit.rps")
    assert p.camera.focal_length == 120.05606183108446
    assert p.camera.principal_point == (0.09949994160901748, 0.0150549430171892)
    assert p.color_transform == ColorTransform()
    sh = p.environment_map.coefficients
    assert sh.shape == (9, 3)
    np.testing.assert_array_equal(sh[0], [0.9027032341391218] * 3)
    np.testing.assert_array_equal(sh[2], [0.19544101431611297] * 3)
    # independent truth: SH.frontal (ambient 0.8 + 0.2 n_z), see params.SHLight.frontal; the
    # AMM file differs by 1.1e-7 relative (float32-level constants in the Scala code)
    np.testing.assert_allclose(sh, SHLight.frontal().coefficients, rtol=2e-7, atol=0)


# -- legacy conversions on synthetic variants ----------------------------------

def test_v1_full_sh_permutation_follows_the_basis_names(shared_data):
    legacy_names = ["1", "x", "y", "z", "z2", "yz", "xz", "xy", "x2-y2"]
    internal_names = ["1", "y", "z", "x", "xy", "yz", "z2", "xz", "x2-y2"]  # reference §2
    data = load_json(shared_data, "renderParametersV1.rps")
    data["sphericalHarmonicsLight"] = [[i, 10 * i, 100 * i] for i in range(9)]
    sh = parse_rps_dict(data).environment_map.coefficients
    expected = [legacy_names.index(n) for n in internal_names]
    np.testing.assert_array_equal(sh[:, 0], expected)
    np.testing.assert_array_equal(sh[:, 2], 100 * np.array(expected))


def test_v1_sensor_is_stored_times_near_and_pp_in_pixels(shared_data):
    data = load_json(shared_data, "renderParametersV1.rps")
    data["camera"].update(near=4.0, sensorSize=[144.0, 96.0], principlePoint=[36.0, 48.0])
    data["image"] = [240, 360]  # [height, width]
    p = parse_rps_dict(data)
    assert p.image_size == ImageSize(width=360, height=240)
    assert p.camera.sensor_size == (36.0, 24.0) and p.camera.near == 4.0
    assert p.camera.principal_point == (2 * 36.0 / 360, 2 * 48.0 / 240)


def test_v2_sensor_is_plain(shared_data):
    data = load_json(shared_data, "renderParametersV2.rps")
    data["camera"].update(near=4.0, sensorSize=[36.0, 24.0])
    assert parse_rps_dict(data).camera.sensor_size == (36.0, 24.0)


def test_v1_directional_light_takes_model_shininess(shared_data):
    data = load_json(shared_data, "renderParametersV1.rps")
    data["sphericalHarmonicsLight"] = []
    data["directionalLight"] = {"ambient": [0.1, 0.2, 0.3], "diffuse": [0.4, 0.5, 0.6],
                                "direction": [0.0, 1.0, 0.0], "specular": [0.7, 0.8, 0.9]}
    data["morphableModel"]["shininess"] = 33.0
    p = parse_rps_dict(data)
    assert p.environment_map.coefficients.shape == (0, 3)
    assert p.directional_light == DirectionalLight((0.1, 0.2, 0.3), (0.4, 0.5, 0.6),
                                                   (0.0, 1.0, 0.0), (0.7, 0.8, 0.9), 33.0)


def test_v2_directional_illumination_and_expression(shared_data):
    data = load_json(shared_data, "renderParametersV2.rps")
    data["illumination"] = {"ambient": [0.1, 0.2, 0.3], "diffuse": [0.4, 0.5, 0.6],
                            "direction": [0.0, 0.0, 1.0], "specular": [0.0, 0.0, 0.0],
                            "shininess": 12.0, "@type": "DirectionalLight"}
    data["renderObject"].update({"@type": "MoMoExpressInstance", "expression": [0.5, -2.0]})
    p = parse_rps_dict(data)
    assert p.environment_map.coefficients.shape == (0, 3)
    assert p.directional_light.shininess == 12.0 and p.directional_light.ambient == (0.1, 0.2, 0.3)
    np.testing.assert_array_equal(p.momo.expression, [0.5, -2.0])


@pytest.mark.parametrize("version,expected", [
    (None, "V1.0"), ("", "V1.0"), ("legacy", "V1.0"), ("1.0", "V1.0"), ("V1.0", "V1.0"),
    ("V2.0", "V2.0"), ("V3.0", "V3.0"), ("V4.0", "V4.0"),
])
def test_version_dispatch(version, expected):
    assert rps_version({} if version is None else {"version": version}) == expected


def test_specular_exponent_is_read_when_present(shared_data):
    for name in ("renderParametersV1.rps", "renderParametersV4.rps"):
        data = load_json(shared_data, name)
        data["specularExponent"] = 37.5
        assert parse_rps_dict(data).specular_exponent == 37.5


# -- writing -------------------------------------------------------------------

@pytest.mark.parametrize("name", VERSIONS + AMM)
def test_read_write_read_is_exact(shared_data, tmp_path, name):
    p = read_rps(shared_data / "scalismo" / name)
    write_rps(tmp_path / "out.rps", p)
    assert_identical(read_rps(tmp_path / "out.rps"), p)


@pytest.mark.parametrize("name", AMM)
def test_writer_reproduces_amm_v4_json(shared_data, name):
    written = format_rps_dict(read_rps(shared_data / "scalismo" / name))
    assert written.pop("specularExponent") == 20.0
    assert written == load_json(shared_data, name)


def test_writer_reproduces_scalismo_v4_json_and_key_order(shared_data):
    fixture = load_json(shared_data, "renderParametersV4.rps")
    written = without_type_tags(format_rps_dict(read_rps(shared_data / "scalismo" /
                                                         "renderParametersV4.rps")))
    del written["specularExponent"]
    assert written == fixture
    assert list(written) == list(fixture)
    for key, block in fixture.items():
        if isinstance(block, dict):
            assert list(written[key]) == list(block), key


def test_random_parameters_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(7)

    def vec(n):
        return tuple(float(v) for v in rng.normal(size=n) * 10.0 ** rng.integers(-12, 12, n))

    p = RenderParameter(
        pose=Pose(float(rng.uniform(0.5, 2)), vec(3), *vec(3)),
        view=View(vec(3), *vec(3)),
        camera=Camera(float(rng.uniform(1, 100)), vec(2), 0.1, 1e7, vec(2), True),
        environment_map=SHLight(rng.normal(size=(16, 3))),
        directional_light=DirectionalLight(vec(3), vec(3), vec(3), vec(3), 5.5),
        momo=MoMoCoefficients(rng.normal(size=7), rng.normal(size=3), rng.normal(size=2),
                              "file:///models/ü model.h5"),
        image_size=ImageSize(317, 211),
        color_transform=ColorTransform(vec(3), -0.0, vec(3)),
        specular_exponent=float(rng.uniform(1, 60)),
    )
    write_rps(tmp_path / "r.rps", p)
    assert_identical(read_rps(tmp_path / "r.rps"), p)
    assert_identical(parse_rps_text(json.dumps(format_rps_dict(p))), p)


def test_default_parameters_round_trip(tmp_path):
    p = default_square()._replace(environment_map=SHLight.empty())
    write_rps(tmp_path / "d.rps", p)
    assert_identical(read_rps(tmp_path / "d.rps"), p)


def test_unwritable_parameters_leave_existing_file_untouched(tmp_path):
    out = tmp_path / "keep.rps"
    out.write_text("previous content")
    bad = default_square()._replace(pose=Pose(scaling=float("nan")))
    with pytest.raises(InputError, match="NaN"):
        write_rps(out, bad)
    assert out.read_text() == "previous content"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.rps"]


# -- bad input -----------------------------------------------------------------

def _mutations():
    def drop(version_name, *keys):
        def f(d):
            target = d
            for k in keys[:-1]:
                target = target[k]
            del target[keys[-1]]
        return version_name, f, "missing field " + ".".join(keys)

    def setv(version_name, keys, value, reason):
        def f(d):
            target = d
            for k in keys[:-1]:
                target = target[k]
            target[keys[-1]] = value
        return version_name, f, reason

    return [
        setv("renderParametersV4.rps", ["version"], "V9.0", "unknown .rps version 'V9.0'"),
        setv("renderParametersV4.rps", ["version"], 4, "version must be a string"),
        drop("renderParametersV1.rps", "camera", "principlePoint"),
        drop("renderParametersV1.rps", "morphableModel", "shininess"),
        drop("renderParametersV2.rps", "illumination", "@type"),
        drop("renderParametersV3.rps", "renderObject", "modelURI"),
        drop("renderParametersV4.rps", "camera", "principalPoint"),
        drop("renderParametersV4.rps", "momo"),
        drop("renderParametersV4.rps", "directionalLight", "shininess"),
        setv("renderParametersV4.rps", ["camera", "sensorSize"], [1.0], "camera.sensorSize"),
        setv("renderParametersV4.rps", ["pose", "yaw"], "0.5", "pose.yaw must be a number"),
        setv("renderParametersV4.rps", ["camera", "orthographic"], 0, "camera.orthographic"),
        setv("renderParametersV4.rps", ["imageSize", "width"], 12.5, "imageSize.width"),
        setv("renderParametersV4.rps", ["environmentMap", "coefficients"], [[1.0, 2.0]],
             "environmentMap.coefficients[0]"),
        setv("renderParametersV4.rps", ["environmentMap", "@type"], "DirectionalLight",
             "environmentMap.@type"),
        setv("renderParametersV2.rps", ["renderObject", "@type"], "MeshFile",
             "renderObject.@type"),
        setv("renderParametersV1.rps", ["sphericalHarmonicsLight"], [[0.0, 0.0, 0.0]] * 16,
             "at most 9"),
        setv("renderParametersV1.rps", ["image"], [480], "image must be"),
    ]


@pytest.mark.parametrize("fixture,mutate,reason", _mutations())
def test_bad_content_raises_format_error_naming_file_and_field(shared_data, tmp_path, fixture,
                                                                mutate, reason):
    data = copy.deepcopy(load_json(shared_data, fixture))
    mutate(data)
    path = tmp_path / "bad.rps"
    path.write_text(json.dumps(data))
    with pytest.raises(FormatError) as info:
        read_rps(path)
    assert str(path) in str(info.value) and reason in str(info.value)
    assert info.value.path == str(path)


@pytest.mark.parametrize("content,reason", [
    (b'{"pose": {', "malformed JSON"),
    (b"", "malformed JSON"),
    (b'{"pose": NaN}', "malformed JSON"),
    (b"[1, 2, 3]", "must hold a JSON object"),
    (b"\xff\xfe\x00garbage", "not UTF-8"),
])
def test_malformed_files(tmp_path, content, reason):
    path = tmp_path / "x.rps"
    path.write_bytes(content)
    with pytest.raises(FormatError, match=reason) as info:
        read_rps(path)
    assert str(path) in str(info.value)


def test_missing_file_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_rps(tmp_path / "absent.rps")
