"""The fit's progress bar: one bar per stage however many chains report, never restarted."""

from __future__ import annotations

import io

from mcmcfit.fitting.progress import FitProgressBar


def _drive(chains: int) -> str:
    out = io.StringIO()
    with FitProgressBar(chains, file=out) as bar:
        for stage, total in (("landmarks", 300), ("image", 1000)):
            for done in range(0, total + 1, 100):
                for c in range(chains):  # the driver reports every chain after each round
                    bar(stage, c, done, total)
    return out.getvalue()


def test_lockstep_chains_share_one_bar_per_stage():
    text = _drive(2)
    # each bar starts once at 0 %: a bar per chain used to restart at every round
    assert text.count(" 0/1000 ") == 1 and text.count(" 0/300 ") == 1
    assert "chains 1-2 landmark stage" in text and "chains 1-2 image stage" in text
    assert "1000/1000" in text and "300/300" in text


def test_one_chain_is_named_as_before_and_quiet_draws_nothing():
    assert "chain 1/1 image stage" in _drive(1)
    out = io.StringIO()
    FitProgressBar(2, disable=True, file=out)("image", 0, 5, 10)
    assert out.getvalue() == ""


def test_the_bar_follows_the_slowest_chain():
    out = io.StringIO()
    bar = FitProgressBar(2, file=out)
    bar("image", 0, 1000, 1000)  # one chain done: the bar is not
    assert bar._bar is not None and bar._bar.n == 0
    bar("image", 1, 1000, 1000)
    assert bar._bar is None and "1000/1000" in out.getvalue()
