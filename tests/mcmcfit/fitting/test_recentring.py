"""Re-centring in the warm-up: a chain whose climb stopped short climbs again from its best draw."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from face_factory import scene, small_face_model, synthetic_target

from mcmcfit.fitting import draw_phases
from mcmcfit.fitting.config import FitConfig
from mcmcfit.fitting.draw_phases import DrawPhases
from mcmcfit.fitting.driver import MAX_RECENTRINGS, _warm_up_recentring
from mcmcfit.fitting.fit import fit
from mcmcfit.fitting.mode import ADOPT_GAP, POLISH_STEPS


class _Session(DrawPhases):
    """The attributes :meth:`DrawPhases.recentre` reads, with log posteriors given by name."""

    def __init__(self, best: float, at_mode: float):
        self.cfg = SimpleNamespace(mode_steps=7)
        self.chain_target = "target"
        self.approx = "approx"
        self.mode = SimpleNamespace(params="mode", log_density=at_mode)
        self.state = SimpleNamespace(params="current")
        self._warm = SimpleNamespace(best_posterior=SimpleNamespace(params="best",
                                                                     log_posterior=best))
        self.values = {"mode": at_mode, "climbed": best + 5.0, "current": best - 1.0}
        self.calls: list[tuple] = []

    def _climb_posterior(self):
        return "posterior"

    def _climb(self, post, params, steps, *, polish=0, free=None):
        self.calls.append(("climb", post, params, steps, polish))
        return SimpleNamespace(params="climbed", log_density=self.values["climbed"])

    def _approximate(self):
        self.calls.append(("approximate", self.mode.params))


@pytest.fixture
def fake_init(monkeypatch):
    def init(params, target, image):
        assert target == "target" and image
        return SimpleNamespace(params=params, log_posterior=session.values[params])

    session = None

    def bind(s):
        nonlocal session
        session = s
        return s

    monkeypatch.setattr(draw_phases, "init", init)
    return bind


def test_a_chain_below_its_best_draw_climbs_from_it_and_reapproximates(fake_init):
    s = fake_init(_Session(best=100.0, at_mode=100.0 - ADOPT_GAP - 1.0))
    found = s.recentre()
    assert found["moved"] and found["gain"] == pytest.approx(ADOPT_GAP + 1.0)
    assert s.calls == [("climb", "posterior", "best", 7, POLISH_STEPS), ("approximate", "climbed")]
    assert s.mode.params == "climbed" and found["log_density"] == 105.0
    assert s.state.params == "current"  # the chain goes on from where it was


@pytest.mark.parametrize("gain", [-40.0, 0.0, ADOPT_GAP])
def test_a_chain_near_its_mode_keeps_its_approximation(fake_init, gain):
    s = fake_init(_Session(best=100.0, at_mode=100.0 - gain))
    found = s.recentre()
    assert not found["moved"] and found["gain"] == pytest.approx(gain)
    assert s.calls == [] and s.mode.params == "mode"


class _Pool:
    """Records the driver's calls; ``recentre`` answers from a script (one list per check)."""

    def __init__(self, moves: list[list[bool]]):
        self.moves, self.calls = list(moves), []

    def call(self, name, *args, **kw):
        self.calls.append((name, args))
        if name == "recentre":
            moved = self.moves.pop(0) if self.moves else [False, False]
            return [{"moved": m, "gain": 50.0 if m else -3.0} for m in moved]
        return [None, None]


def _warmups(pool):
    return [args[0] for name, args in pool.calls if name == "warmup"]


def test_the_warmup_is_checked_after_every_window_and_not_extended_without_a_move():
    pool, stopping = _Pool([]), {}
    ran = _warm_up_recentring(pool, FitConfig(adapt_window=100), 250, stopping)
    assert ran == 250 and _warmups(pool) == [100, 100, 50]
    assert [c["warmup_steps"] for c in stopping["recentring"]] == [100, 200, 250]
    assert all(c["moved"] == [False, False] for c in stopping["recentring"])


def test_a_move_in_the_last_window_adds_one_window():
    pool, stopping = _Pool([[False, False], [False, False], [True, False]]), {}
    ran = _warm_up_recentring(pool, FitConfig(adapt_window=100), 250, stopping)
    assert ran == 350 and _warmups(pool) == [100, 100, 50, 100]
    assert stopping["recentring"][2]["moved"] == [True, False]


def test_recentrings_are_capped():
    pool, stopping = _Pool([[True, True]] * 10), {}
    ran = _warm_up_recentring(pool, FitConfig(adapt_window=100), 200, stopping)
    assert len(stopping["recentring"]) == MAX_RECENTRINGS
    # the last re-centring still gets its window on the new approximation
    assert ran == 100 * (MAX_RECENTRINGS + 1)
    assert sum(n == "recentre" for n, _ in pool.calls) == MAX_RECENTRINGS


def test_without_recentring_the_warmup_runs_in_one_call():
    pool, stopping = _Pool([[True, True]]), {}
    ran = _warm_up_recentring(pool, FitConfig(adapt_window=100, recentre=False), 250, stopping)
    assert ran == 250 and pool.calls == [("warmup", (250,))] and "recentring" not in stopping


def test_every_chain_recentres_in_a_real_fit_when_any_gain_counts(monkeypatch):
    """The machinery end to end (climb from the best draw, new approximation and moves, the
    chain going on): with a gap of -inf every check re-centres, up to the cap."""
    from mcmcfit.fitting import driver

    monkeypatch.setattr(driver, "RECENTRE_GAP", -np.inf)
    model = small_face_model()
    image, clicks = synthetic_target(model, scene(64, 64, yaw=0.25, pitch=-0.1))
    # the whole warm-up in re-centring windows (the Fisher widening would split it at 60 %)
    cfg = FitConfig(steps=50, landmark_steps=200, warmup_steps=150, adapt_window=50,
                    check_every=50, chains=1, parallel=False, sigma_lm=2.0, metric="gauss-newton")
    res = fit(image, clicks, model, config=cfg, seed=6)
    checks = res.stopping["recentring"]
    assert [c["moved"] for c in checks] == [[True]] * MAX_RECENTRINGS
    assert all(np.isfinite(g) for c in checks for g in c["gains"])
    # three windows, each re-centred; the last one's new approximation gets one more window
    assert res.stopping["warmup_steps"] == 50 * (MAX_RECENTRINGS + 1)
    for c in res.chains:
        assert c.warmup.steps == 200 and c.stage2.steps == 50
        assert np.all(np.isfinite(c.stage2.log_lik_img))
        assert c.stage2.accepted.mean() > 0.05  # the rebuilt moves still move
