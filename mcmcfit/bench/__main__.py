"""``python -m mcmcfit.bench render|fit [options]``: same as ``mcmcfit bench render|fit``.

This module imports :mod:`mcmcfit` (the BLAS thread default) and
:mod:`mcmcfit.commands.bench`.
"""

import argparse
import sys

import mcmcfit  # noqa: F401  (sets OPENBLAS_NUM_THREADS before numpy loads BLAS)
from mcmcfit.commands.bench import add_fit_arguments, add_render_arguments, run_fit, run_render


def main(argv=None) -> int:
    """Run the benchmark ``argv`` names (default: ``sys.argv[1:]``); return the exit status."""
    parser = argparse.ArgumentParser(prog="python -m mcmcfit.bench")
    sub = parser.add_subparsers(dest="bench_command", metavar="BENCHMARK", required=True)
    add_render_arguments(sub.add_parser("render", help="ms per sampler step per proposal kind"))
    add_fit_arguments(sub.add_parser("fit", help="default schedule on the demo case"))
    args = parser.parse_args(argv)
    return run_fit(args) if args.bench_command == "fit" else run_render(args)


if __name__ == "__main__":
    sys.exit(main())
