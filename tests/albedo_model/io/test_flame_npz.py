"""The AlbedoMM FLAME texture-space albedo npz (albedo_model.io.flame_npz)."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

from albedo_model.errors import FormatError
from albedo_model.io.flame_npz import FlameAlbedo, read_flame_albedo_npz, write_flame_albedo_npz

H, W, K = 6, 5, 4


def release_like(seed: int = 0) -> dict[str, np.ndarray]:
    """Arrays with the release's keys and layout: BGR maps, scaled orthogonal columns."""
    rng = np.random.default_rng(seed)
    d = H * W * 3
    q = np.linalg.qr(rng.standard_normal((d, 2 * K)))[0]
    sd = np.array([0.3, 0.2, 0.1, 0.05])
    return {
        "MU": rng.uniform(0, 1, (H, W, 3)),
        "PC": (q[:, :K] * sd).reshape(H, W, 3, K),
        "specMU": rng.uniform(0, 0.3, (H, W, 3)),
        "specPC": (q[:, K:] * sd / 2).reshape(H, W, 3, K),
        "vt": rng.uniform(0, 1, (11, 2)),
        "ft": rng.integers(0, 11, (7, 3)),
    }


def test_reads_release_layout(tmp_path: Path) -> None:
    arrays = release_like()
    np.savez(tmp_path / "flame.npz", **arrays)
    model = read_flame_albedo_npz(tmp_path / "flame.npz", dtype=np.float64)
    assert model.texture_shape == (H, W, 3)
    assert model.diffuse.rank == model.specular.rank == K
    assert np.array_equal(model.uv, arrays["vt"]) and np.array_equal(model.uv_faces, arrays["ft"])
    c = np.array([0.5, -1.0, 2.0, 0.25])
    for mu, pc, part in (("MU", "PC", model.diffuse), ("specMU", "specPC", model.specular)):
        bgr = arrays[mu] + arrays[pc] @ c  # the file's own model, in BGR
        rgb = part.instance(c).reshape(H, W, 3)
        assert np.allclose(rgb, bgr[..., ::-1], rtol=0, atol=1e-12)
        b = part.basis
        assert np.allclose(b.T @ b, np.eye(K), atol=1e-12)
    assert np.allclose(model.diffuse.variance, [0.09, 0.04, 0.01, 0.0025], rtol=1e-12)


def test_rank_dtype_and_rgb_order(tmp_path: Path) -> None:
    arrays = release_like(1)
    np.savez(tmp_path / "flame.npz", **arrays)
    model = read_flame_albedo_npz(tmp_path / "flame.npz", rank=2, channel_order="rgb")
    assert model.diffuse.rank == model.specular.rank == 2
    assert model.diffuse.basis.dtype == np.float32
    assert np.allclose(model.diffuse.mean, arrays["MU"].ravel().astype(np.float32))


def test_write_read_round_trip(tmp_path: Path) -> None:
    np.savez(tmp_path / "a.npz", **release_like(2))
    model = read_flame_albedo_npz(tmp_path / "a.npz", dtype=np.float64)
    write_flame_albedo_npz(model, tmp_path / "b.npz")
    back = read_flame_albedo_npz(tmp_path / "b.npz", dtype=np.float64)
    for name in ("diffuse", "specular"):
        a, b = getattr(model, name), getattr(back, name)
        assert np.array_equal(a.mean, b.mean)
        assert np.allclose(a.basis, b.basis, rtol=0, atol=1e-14)
        assert np.allclose(a.variance, b.variance, rtol=1e-13)
    assert isinstance(back, FlameAlbedo) and back.texture_shape == model.texture_shape


def test_diffuse_only(tmp_path: Path) -> None:
    arrays = release_like(3)
    np.savez(tmp_path / "d.npz", MU=arrays["MU"], PC=arrays["PC"])
    model = read_flame_albedo_npz(tmp_path / "d.npz")
    assert model.specular is None and model.uv is None


def _bad(tmp_path: Path, how: str) -> Path:
    path = tmp_path / f"bad-{how}.npz"
    arrays = release_like(4)
    if how == "object-array":
        arrays["PC"] = np.array([{"evil": 1}], dtype=object)
        np.savez(path, **arrays)
    elif how == "pickle-file":
        path.write_bytes(pickle.dumps({"MU": 1}))
    elif how == "truncated":
        np.savez(path, **arrays)
        path.write_bytes(path.read_bytes()[:300])
    elif how == "not-npz":
        path.write_text("hello")
    elif how == "missing-key":
        np.savez(path, MU=arrays["MU"])
    elif how == "wrong-shape":
        arrays["PC"] = arrays["PC"][:, :-1]
        np.savez(path, **arrays)
    elif how == "nan":
        arrays["specPC"][0, 0, 0, 0] = np.nan
        np.savez(path, **arrays)
    elif how == "rank-mismatch":
        arrays["specPC"] = arrays["specPC"][..., :2]
        np.savez(path, **arrays)
    return path


BAD = {
    "object-array": "needs pickle; refusing to unpickle",
    "pickle-file": "needs pickle; refusing to unpickle",
    "truncated": "cannot",
    "not-npz": "not an .npz archive",
    "missing-key": "missing arrays MU and PC (found: MU)",
    "wrong-shape": "PC has shape",
    "nan": "specPC contains NaN",
    "rank-mismatch": "specPC has 2 components",
}


@pytest.mark.parametrize("how", sorted(BAD))
def test_bad_input(tmp_path: Path, how: str) -> None:
    path = _bad(tmp_path, how)
    with pytest.raises(FormatError) as err:
        read_flame_albedo_npz(path)
    assert str(path) in str(err.value) and BAD[how] in str(err.value)
