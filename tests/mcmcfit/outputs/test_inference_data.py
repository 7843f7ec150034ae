"""posterior.nc: InferenceData groups against the chain records, netCDF round trip, ArviZ reads it."""

from __future__ import annotations

import json

import matplotlib
import numpy as np
import pytest

from albedo_model.params import default_square, fit_to_image_size
from mcmcfit.outputs.inference_data import inference_data, write_posterior_nc
from mcmcfit.sampling.chain import BestSample, ChainRecord, ChainResult
from mcmcfit.sampling.derived import RegionAlbedo, region_albedo_means
from mcmcfit.sampling.diagnostics import arviz
from mcmcfit.sampling.param_vector import ParamLayout

matplotlib.use("Agg")
LAYOUT = ParamLayout(4, 3, 5, 2)
TEMPLATE = fit_to_image_size(default_square(), 32, 32)


def _record(rng, n, thin, names, stage="image"):
    steps = n * thin
    x = rng.normal(size=(n, LAYOUT.size)).cumsum(axis=0) * 0.1
    x[:, LAYOUT.index("pose.scaling")] = 1.0
    best = BestSample(TEMPLATE, -1, 0.0, 0.0, 0.0)
    return ChainRecord(stage, "mh", thin, steps, LAYOUT, np.arange(n) * thin + thin - 1, x,
                       rng.normal(size=steps), rng.normal(size=steps), rng.normal(size=steps),
                       rng.integers(0, len(names), steps).astype(np.int32), tuple(names),
                       rng.random(steps) < 0.3, np.zeros(steps, np.int8), best, best, best)


def _chains(rng, warmup: bool):
    out = []
    for i, names in enumerate((("light", "shape"), ("shape", "light", "pose"))):
        c = ChainResult(i, 7, (i,), None, _record(rng, 40 - 3 * i, 5, names))
        if warmup:
            c.warmup = _record(rng, 12, 5, names)  # the field another change adds
        out.append(c)
    return out


BASIS = RegionAlbedo(("nose", "chin"), np.full((2, 3), 0.4),
                     np.random.default_rng(9).normal(0, 0.01, (2, LAYOUT.n_albedo, 3)))


def test_groups_hold_the_chains(tmp_path):
    rng = np.random.default_rng(0)
    chains = _chains(rng, warmup=True)
    image = rng.random((6, 5, 3))
    idata = inference_data(chains, LAYOUT, TEMPLATE, BASIS,
                           observed={"image": image, "landmarks": {"b": (1.0, 2.0), "a": (3, 4)}},
                           attrs={"seed": 11, "noise_model": {"sigma_px": 0.04}})
    assert set(idata.groups()) == {"posterior", "sample_stats", "warmup_posterior",
                                   "warmup_sample_stats", "observed_data"}
    post, stats = idata.posterior, idata.sample_stats
    assert post.sizes["chain"] == 2 and post.sizes["draw"] == 37  # cut to the shortest chain
    assert idata.warmup_posterior.sizes["draw"] == 12
    for c, ch in enumerate(chains):
        rec = ch.stage2
        s = rec.samples[:37]
        np.testing.assert_array_equal(post["pose"].sel(pose_param="yaw")[c], s[:, 0])
        np.testing.assert_array_equal(post["camera"].sel(camera_param="pp_y")[c], s[:, 9])
        np.testing.assert_array_equal(post["light"].sel(sh_coefficient=2, channel="g")[c],
                                      s[:, LAYOUT.index("light.2.g")])
        np.testing.assert_array_equal(post["color_transform"].sel(
            color_transform_param="offset_b")[c], s[:, LAYOUT.index("color_transform.offset.b")])
        np.testing.assert_array_equal(post["albedo"][c], s[:, LAYOUT.slice("albedo")])
        np.testing.assert_array_equal(post["specular_exponent"][c],
                                      s[:, LAYOUT.index("specular_exponent")])
        np.testing.assert_allclose(post["albedo_mean"].sel(region="chin", channel="b")[c],
                                   region_albedo_means(s[:, LAYOUT.slice("albedo")], BASIS)[:, 1, 2])
        steps = rec.sample_step[:37]
        np.testing.assert_array_equal(stats["lp"][c], rec.log_posterior[steps])
        np.testing.assert_array_equal(stats["log_likelihood_image"][c], rec.log_lik_img[steps])
        np.testing.assert_array_equal(stats["step"][c], steps)
        names = json.loads(stats.attrs["proposal_names"])
        got = [names[k] for k in stats["proposal"][c].values]
        assert got == [rec.proposal_names[k] for k in rec.proposal[steps]]
        # acceptance over the steps since the previous draw, by brute force
        prev = -1
        for d, s_ in enumerate(steps):
            assert stats["acceptance_rate"][c, d] == pytest.approx(rec.accepted[prev + 1:s_ + 1].mean())
            prev = s_
        np.testing.assert_array_equal(idata.warmup_posterior["shape"][c],
                                      ch.warmup.samples[:12, LAYOUT.slice("shape")])
    np.testing.assert_array_equal(idata.observed_data["image"], image)
    assert list(idata.observed_data["landmark"].values) == ["a", "b"]
    np.testing.assert_array_equal(idata.observed_data["landmarks"].sel(landmark="b"), [1.0, 2.0])
    assert post.attrs["seed"] == 11 and json.loads(post.attrs["noise_model"]) == {"sigma_px": 0.04}
    assert "template_rps" in post.attrs


def test_without_warmup_records_the_burn_in_is_the_warmup():
    rng = np.random.default_rng(1)
    chains = _chains(rng, warmup=False)
    idata = inference_data(chains, LAYOUT, TEMPLATE, None, burn_fraction=0.25)
    assert "albedo_mean" not in idata.posterior
    start = int(0.25 * 37)
    assert idata.posterior.sizes["draw"] == 37 - start
    assert idata.warmup_posterior.sizes["draw"] == start
    np.testing.assert_array_equal(idata.posterior["shape"][1],
                                  chains[1].stage2.samples[start:37, LAYOUT.slice("shape")])
    np.testing.assert_array_equal(idata.warmup_sample_stats["lp"][0],
                                  chains[0].stage2.log_posterior[chains[0].stage2.sample_step[:start]])
    assert "warmup_posterior" not in inference_data(chains, LAYOUT, TEMPLATE, None).groups()


@pytest.mark.filterwarnings("ignore::matplotlib.MatplotlibDeprecationWarning")
@pytest.mark.filterwarnings("ignore:Your data appears to have a single value")  # pose.scaling
def test_posterior_nc_round_trip_and_arviz_reads_it(tmp_path):
    rng = np.random.default_rng(2)
    idata = inference_data(_chains(rng, warmup=True), LAYOUT, TEMPLATE, BASIS,
                           observed={"image": rng.random((4, 4, 3))},
                           attrs={"seed": 3, "software": {"mcmcfit": "0.1.0"}})
    path = tmp_path / "posterior.nc"
    write_posterior_nc(path, idata)
    az = arviz()
    back = az.from_netcdf(path)
    assert set(back.groups()) == set(idata.groups())
    for group in idata.groups():
        a, b = idata[group], back[group]
        assert set(a.data_vars) == set(b.data_vars)
        for v in a.data_vars:
            np.testing.assert_array_equal(a[v].values, b[v].values)
    assert json.loads(back.posterior.attrs["software"]) == {"mcmcfit": "0.1.0"}
    with np.errstate(all="ignore"):
        table = az.summary(back)
    assert "pose[yaw]" in table.index and "albedo_mean[nose, r]" in table.index
    assert {"r_hat", "ess_bulk", "ess_tail"} <= set(table.columns)
    axes = az.plot_trace(back, var_names=["pose", "albedo_mean", "specular_exponent"])
    assert axes.shape[1] == 2
    import matplotlib.pyplot as plt

    plt.close("all")


def test_without_an_image_stage_the_landmark_stage_is_stored(tmp_path):
    rng = np.random.default_rng(3)
    chains = [ChainResult(i, 7, (i,), _record(rng, 20, 5, ("pose",), stage="landmarks"), None)
              for i in range(2)]
    idata = inference_data(chains, LAYOUT, TEMPLATE, BASIS)
    assert idata.posterior.attrs["stage"] == "landmarks" and idata.posterior.sizes["draw"] == 20
    np.testing.assert_array_equal(idata.posterior["pose"][1], chains[1].stage1.samples[:, :7])
    empty = inference_data([ChainResult(0, 7, (0,), None, None)], LAYOUT, TEMPLATE, None)
    assert empty.posterior.sizes["chain"] == 0
    write_posterior_nc(tmp_path / "empty.nc", empty)
    assert arviz().from_netcdf(tmp_path / "empty.nc").posterior.sizes["chain"] == 0
