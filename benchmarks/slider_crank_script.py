"""The scipy user's whole program: the slider-crank simulated with `solve_ivp` and its result
written to a file, as a script someone who does not use jaxdeploy would run
(`python -m benchmarks.slider_crank_script --rtol R --atol A --out FILE`).

It is the peer of `jaxdeploy simulate slider_crank` as a whole process
(`benchmarks/whole_process.py`): start the interpreter, import numpy and scipy, integrate the
model of `benchmarks/scipy_peer.py` (minimal coordinates, onset and separation events) over
two crank revolutions (the scene's t_end, 0.024 s), save the slider position at the same 2001
times, write them. No plots (a scipy user would need matplotlib for those; jaxdeploy writes
two).
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from .scipy_peer import SliderCrankPeer


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--method", default="LSODA")
    parser.add_argument("--rtol", type=float, required=True)
    parser.add_argument("--atol", type=float, required=True)
    parser.add_argument("--t-end", type=float, default=0.024)
    parser.add_argument("--n-save", type=int, default=2001)
    parser.add_argument("--out", required=True, help="the .npz file written")
    args = parser.parse_args(argv)
    ts = np.linspace(0.0, args.t_end, args.n_save)
    x, evaluations = SliderCrankPeer().solve(ts, args.method, args.rtol, args.atol)
    np.savez(args.out, t=ts, x=x)
    print(f"{args.method} rtol={args.rtol:g}: {evaluations} evaluations, wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
