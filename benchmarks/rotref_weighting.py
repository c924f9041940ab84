"""The real references' roll/pitch inertia under the calibration's two readings of the
roll/pitch residual (issue 45 item 2): as the evidence takes it (``calibrate(...,
torque_side=False)``, the rule before) and on the torque side in the band where the rotors
drive the body (:class:`quadsim.gap.calibrate.TorqueSide`, the rule now).

Per reading: the pooled shared values (inertia error xx, yy, zz; rate damping x, y) with
their bound flags, each reference's own value (the scatter's Gauss-Newton step), and the
band RMS (N m) of the references' Mx, My residual at the calibrated values (0-2, 2-4, 4-16,
16-50 Hz; Welch at the fit rate), with the CPU time of the calibration.

Usage (needs the shared data; not run by the tests)::

    D=../shared/data/crazyflie21_brushless
    PYTHONPATH=$PWD python -m benchmarks.rotref_weighting $D/nominal/*.csv.gz
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import signal

from quadsim.core.executor import limit_numeric_threads
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import prepare
from quadsim.gap.fitting import residuals
from quadsim.logs.flightlog import load_log
from quadsim.vehicle.params import load_params

KEYS = ("inertia_error.xx", "inertia_error.yy", "inertia_error.zz", "rate_damping.x",
        "rate_damping.y")
BANDS_HZ = ((0.0, 2.0), (2.0, 4.0), (4.0, 16.0), (16.0, 50.0))


def band_rms(ref, flights) -> np.ndarray:
    """(2, len(BANDS_HZ)) RMS (N m) of the Mx, My residual per band, pooled over flights."""
    power = np.zeros((2, len(BANDS_HZ)))
    total = 0
    for f in flights:
        s = ref.align(f.fit) if hasattr(ref, "align") else f.fit
        r = residuals(s, ref.params, ref.effects(), rotor_channel=ref.rotor)[:, 3:5]
        fs = 1.0 / float(np.median(np.diff(s.t)))
        freq, pxx = signal.welch(r, fs=fs, axis=0, nperseg=min(512, len(r)))
        df = freq[1] - freq[0]
        for j, (lo, hi) in enumerate(BANDS_HZ):
            sel = (freq >= lo) & (freq < hi)
            power[:, j] += pxx[sel].sum(axis=0) * df * len(r)
        total += len(r)
    return np.sqrt(power / total)


@limit_numeric_threads
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="+")
    ap.add_argument("--model", default="crazyflie21")
    args = ap.parse_args()
    params = load_params(args.model)
    flights = prepare([load_log(p) for p in args.logs], params)
    for side in (False, True):
        t0 = time.process_time()
        ref = calibrate(flights, params, torque_side=side)
        cpu = time.process_time() - t0
        names = list(ref.candidate.parameter_names)
        print(f"== torque_side={side}  ({len(flights)} references, {cpu:.1f} s CPU)")
        for key in KEYS:
            j = names.index(key)
            own = ref.per_flight.values[:, j]
            print(f"  {key:18s} pooled {ref.theta[j]:+9.4g}  se {ref.se_pool[j]:.3g}  "
                  f"scatter {ref.scatter[j]:.3g}  bound {ref.at_bound.get(key, '-'):5s}  "
                  f"per flight median {np.median(own):+.3g} [{own.min():+.3g}, {own.max():+.3g}]")
            print("    per flight: " + " ".join(f"{v:+.2f}" for v in own))
        rms = band_rms(ref, flights)
        for a, axis in enumerate(("Mx", "My")):
            print(f"  {axis} residual RMS by band " + ", ".join(
                f"{lo:g}-{hi:g} Hz {rms[a, j]:.2e}" for j, (lo, hi) in enumerate(BANDS_HZ))
                + " N m")
        print(f"  rotor timing {1e3 * ref.rotor_shift_s:+.1f} ms; "
              f"sigma Mx My Mz {ref.sigma[3]:.2e} {ref.sigma[4]:.2e} {ref.sigma[5]:.2e}")


if __name__ == "__main__":
    main()
