"""Linear ARX reference for the forward model's velocity error on an `ocm mor` data set.

Least squares of dX_S/dt(t+1) on the last `lags` steps of [X_S, P_S, tau] (optionally with
dX_S/dt), fitted on all but the last 20 % of the sequences and scored on those, as the mean
Euclidean TCP velocity error in mm/s. `--late` pairs each state with the inputs of its own row
(the step that led to it) instead of the next row's (the step it drives), to show what the
pairing costs. Usage: python3 arx_floor.py DS [--lags 10] [--velocity] [--late]
"""

import argparse
import json
import os

import numpy as np


def load(ds):
    man = json.load(open(os.path.join(ds, "manifest.json")))
    arrays = {}
    for name in ("sequence", "pressure_kpa", "tip_force_n", "xs", "xs_dot"):
        parts = [
            np.load(os.path.join(ds, d, name + ".npy"))
            for d in sorted(os.listdir(ds))
            if d.startswith("shard-")
        ]
        arrays[name] = np.concatenate(parts)
    seq = arrays["sequence"][:, 0]
    out = []
    for s in np.unique(seq):
        rows = seq == s
        out.append({k: v[rows] for k, v in arrays.items()})
    return man, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("ds")
    ap.add_argument("--lags", type=int, default=10)
    ap.add_argument("--velocity", action="store_true")
    ap.add_argument("--late", action="store_true")
    a = ap.parse_args()
    _, seqs = load(a.ds)
    shift = 0 if a.late else 1
    feats, targets = [], []
    for q in seqs:
        n = len(q["xs"])
        k = np.arange(a.lags, n - 2)
        cols = [np.ones((len(k), 1))]
        for lag in range(a.lags):
            cols += [q["xs"][k - lag], q["pressure_kpa"][k - lag + shift], q["tip_force_n"][k - lag + shift]]
            if a.velocity:
                cols.append(q["xs_dot"][k - lag])
        feats.append(np.hstack(cols))
        targets.append(q["xs_dot"][k + 1])
    n_test = int(round(0.2 * len(seqs)))
    a_fit, y_fit = np.vstack(feats[:-n_test]), np.vstack(targets[:-n_test])
    w, *_ = np.linalg.lstsq(a_fit, y_fit, rcond=None)
    a_test, y_test = np.vstack(feats[-n_test:]), np.vstack(targets[-n_test:])
    err = np.linalg.norm((a_test @ w - y_test)[:, :3], axis=1).mean() * 1e3
    print(json.dumps({"lags": a.lags, "velocity": a.velocity, "late": a.late, "velocity_error_mm_s": err}))


if __name__ == "__main__":
    main()
