"""Which moves of a fit move what: expected squared jump per step and per second, by move.

Reads a result folder's ``chain.h5`` (kept image-stage draws, recorded every
step: ``thin`` 1, the default) and, for each move of the mixture, sums the
squared change of every kept draw it made (0 when rejected), in units of each
quantity's posterior sd (the kept draws' pooled sd), over groups of
quantities: the shape coefficients, pose and focal length, albedo, light,
colour transform, and any quantities named with ``--slowest`` (e.g. those the
summary's convergence table lists as worst). Divided by the number of steps
the move made and by the seconds they took, it is the move's expected squared
jump distance (ESJD) per step and per second: ``1 - ESJD / 2`` is the lag-1
autocorrelation a chain of that move alone would have, so per second it says
which move buys mixing of those quantities most cheaply in this fit.

Usage: ``python benchmarks/move_jumps.py RESULT/chain.h5 [--slowest shape.6,shape.3]``.
"""

from __future__ import annotations

import argparse

import h5py
import numpy as np

GROUPS = {"shape": ("shape.",), "pose+focal": ("pose.", "camera.focal_length"),
          "albedo": ("albedo.",), "light": ("light.",), "colour": ("color_transform",)}


def _text(values) -> list[str]:
    return [v.decode() if isinstance(v, bytes) else str(v) for v in values]


def move_jumps(path: str, slowest: list[str]) -> tuple[list[str], dict[str, dict]]:
    """Return the group names and, per move, its steps, seconds and summed squared jumps."""
    with h5py.File(path, "r") as f:
        names = _text(f["parameter_names"][()])
        chains = [f[c]["stage2"] for c in f if c.startswith("chain_") and "stage2" in f[c]]
        if not chains:
            raise SystemExit(f"{path}: no kept image-stage draws")
        if any(g["samples"].shape[0] != g["proposal"].shape[0] for g in chains):
            raise SystemExit(f"{path}: draws are thinned; the jumps need every step (thin 1)")
        sd = np.concatenate([g["samples"][()] for g in chains]).std(axis=0)
        sd[sd == 0] = 1.0
        groups = {k: [i for i, n in enumerate(names) if n.startswith(p)]
                  for k, p in GROUPS.items()}
        if slowest:
            groups["slowest"] = [names.index(n) for n in slowest]
        rows: dict[str, dict] = {}
        for g in chains:
            x = g["samples"][()] / sd
            moves = _text(g["proposal_names"][()])
            prop, sec = g["proposal"][()], g["step_seconds"][()].astype(np.float64)
            jump = np.zeros_like(x)
            jump[1:] = np.diff(x, axis=0) ** 2
            for i in np.unique(prop):
                sel = prop == i
                sel[0] = False  # the first draw's jump is from outside the record
                r = rows.setdefault(moves[i], {"steps": 0, "seconds": 0.0,
                                               **{k: 0.0 for k in groups}})
                r["steps"] += int(sel.sum())
                r["seconds"] += float(sec[sel].sum())
                for k, ix in groups.items():
                    r[k] += float(jump[sel][:, ix].sum())
    return list(groups), rows


def main(argv: list[str] | None = None) -> None:
    """Print each move's share of the steps, its time per step and its ESJD per step and second."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("chain", help="a result folder's chain.h5")
    ap.add_argument("--slowest", default="", help="comma-separated quantity names")
    args = ap.parse_args(argv)
    groups, rows = move_jumps(args.chain, [s for s in args.slowest.split(",") if s])
    total = sum(r["steps"] for r in rows.values())
    print(f"{'move':27s} {'share':>6s} {'ms/step':>8s}  " + "  ".join(
        f"{g + ' /step':>14s} {'/s':>7s}" for g in groups))
    for move, r in sorted(rows.items(), key=lambda kv: -kv[1]["seconds"]):
        n, t = max(r["steps"], 1), max(r["seconds"], 1e-12)
        print(f"{move:27s} {r['steps'] / total:6.3f} {1e3 * t / n:8.1f}  " + "  ".join(
            f"{r[g] / n:14.3f} {r[g] / t:7.1f}" for g in groups))


if __name__ == "__main__":
    main()
