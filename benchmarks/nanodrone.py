"""The published nano-drone prediction benchmark: windows, its two baselines and its scoring.

Busetto, Cereda, Forgione, Maroni, Piga, Palossi, "Nonlinear System Identification for a
Nano-drone Benchmark", Control Engineering Practice 172 (2026) 106871 (arXiv 2512.14450;
code and data idsia-robotics/nanodrone-sysid-benchmark): Crazyflie 2.1 Brushless flights at
100 Hz, state estimate plus measured rotor speeds. Protocol (from the authors' code,
``identification/dataset.py`` and ``results/model_comparison.ipynb``):

* a window starts at every sample ``i = 0 .. N - H - 2`` of each test run (H = 50; N - H - 1
  windows per run, 19,347 on the three melon runs); the model gets the true state at ``i``
  and the H measured rotor speeds ``Omega[i .. i + H - 1]`` (rad/s, zero-order hold, 0.01 s
  each) and predicts the states at ``i + 1 .. i + H`` open loop;
* errors per horizon h: ``||p_hat - p||`` (m), ``||v_hat - v||`` (m/s),
  ``||w_hat - w||`` (rad/s) and an attitude angle (rad), averaged over windows; reported at
  h = 1, 10, 50 and as SimErr = the sum over h = 1..50.

Two scorings (:func:`score`):

``published``
    exactly what the published table computes: the windows of all runs are concatenated and
    the truth at horizon h is taken by shifting the concatenated h = 1 truths by h - 1 rows
    (the last h - 1 windows of a run are scored against the next run's first states; the
    last run's are dropped); and the attitude angle is ``2 atan2(|d[1:4]|, d[0])`` of
    ``d = conj(a) * b`` with the quaternions stored (x, y, z, w) but multiplied as if they
    were (w, x, y, z) -- the authors' notebook converts rotation vectors to xyzw quaternions
    and hands them to a scalar-first geodesic. Found by reproduction: with the true geodesic
    the Physics row's attitude SimErr is 5.085 instead of the published 5.101; with this
    reading 5.101. It is a rotation-dependent distance, not the geodesic.
``per_run``
    each run scored on its own windows and its own truth, the true geodesic angle
    ``2 atan2(|vec(q^-1 q_hat)|, |w(q^-1 q_hat)|)``, the runs' curves averaged.

Baselines (:func:`naive_prediction`, :func:`physics_prediction`): hold the state; the
authors' physics model (thrust ``Kt sum Omega^2`` along body z, clipped at
``thrust_to_weight m g``, gravity, RK4 at 0.01 s with the quaternion renormalised at every
stage, body rate held constant: their code multiplies the angular acceleration by zero).
Their constants: m = 0.045 kg, g = 9.81 m/s^2, Kt = 3.72e-8 N s^2/rad^2, thrust-to-weight 2.

Rotor-speed timing (:func:`align_rotor_speeds`): the authors shift each run's rotor speeds by
one integer lag (cross-correlation of sum Omega^2 with the body-z acceleration). What turns
the vehicle is the torque, so the rotor speeds can also be timed against the body rate: the
lag at which the integrated Omega_i^2 best explains the body rate
(:func:`quadsim.logs.delays.estimate_delays`: rotor delay minus gyro delay, both against
the attitude). The shift uses only the run's own rotor speeds and body rates -- inputs and
initial states the protocol hands the model -- but of the whole run, not of one window.

Units SI throughout; quaternions scalar-first body to world, as everywhere in quadsim.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from quadsim.core.frames import (
    quat_conjugate,
    quat_derivative,
    quat_multiply,
    quat_normalize,
    rotate,
)
from quadsim.logs.delays import estimate_delays
from quadsim.logs.flightlog import FlightLog

__all__ = [
    "HORIZON",
    "PERIOD",
    "PUBLISHED",
    "QUANTITIES",
    "Windows",
    "align_rotor_speeds",
    "curves",
    "make_windows",
    "naive_prediction",
    "of_run",
    "physics_prediction",
    "rate_skill",
    "rotor_delay",
    "score",
    "summary",
]

HORIZON = 50            # steps per window
PERIOD = 0.01           # s, sample period of the processed runs
QUANTITIES = ("p", "v", "R", "w")
REPORTED = (1, 10, 50)  # horizons of the published table

#: Published rows (test = melon), in the order [h1, h10, h50, SimErr] per quantity; from the
#: authors' notebook results/model_comparison.ipynb, table tab:numerical_performance, as
#: copied into ../shared/data/nanodrone_cf21bl/README.md. Units m, m/s, rad, rad/s.
PUBLISHED = {
    "naive": {"p": [0.0143, 0.1430, 0.6797, 17.7878], "v": [0.0329, 0.3182, 1.4749, 38.9241],
              "R": [0.0071, 0.0692, 0.3041, 8.2138], "w": [0.0796, 0.3596, 0.8837, 29.0866]},
    "physics": {"p": [0.0013, 0.0126, 0.1269, 2.3223], "v": [0.0080, 0.0570, 0.5781, 10.6232],
                "R": [0.0011, 0.0205, 0.2544, 5.1013], "w": [0.0796, 0.3596, 0.8837, 29.0866]},
    "mlp": {"p": [0.0032, 0.0305, 0.1712, 4.0519], "v": [0.0116, 0.0890, 0.5720, 12.5809],
            "R": [0.0022, 0.0331, 0.2268, 6.0591], "w": [0.1138, 0.5949, 0.9005, 35.5735]},
    "hybrid": {"p": [0.0016, 0.0166, 0.1119, 2.3625], "v": [0.0092, 0.0613, 0.5556, 10.4033],
               "R": [0.0027, 0.0376, 0.2306, 6.1534], "w": [0.0912, 0.4880, 0.5979, 28.9873]},
    "lstm": {"p": [0.0079, 0.0390, 0.2572, 5.9711], "v": [0.0247, 0.1175, 0.7407, 16.7207],
             "R": [0.0066, 0.0372, 0.2325, 5.6525], "w": [0.1021, 0.4292, 1.2407, 35.8353]},
}

# The authors' physics baseline (identification/models.py, test script constants).
MASS = 0.045            # kg
GRAVITY = 9.81          # m/s^2
KT = 3.72e-8            # N s^2/rad^2
THRUST_TO_WEIGHT = 2.0  # thrust clip, times m g


@dataclass(frozen=True)
class Windows:
    """All prediction windows of a set of runs, concatenated in run order.

    ``position, velocity, quat, body_rate``: (B, 3/3/4/3) true state at each window start;
    ``rotor_speed``: (B, H, R) measured rotor speeds held over the H steps (rad/s);
    ``truth``: dict quantity -> (B, H, k) true states at steps 1..H of each window;
    ``run``: (B,) index of the run each window belongs to; ``names``: the runs' names."""

    position: np.ndarray
    velocity: np.ndarray
    quat: np.ndarray
    body_rate: np.ndarray
    rotor_speed: np.ndarray
    truth: dict
    run: np.ndarray
    names: tuple

    def __len__(self) -> int:
        return len(self.run)

    def initial(self) -> dict:
        return {"position": self.position, "velocity": self.velocity, "quat": self.quat,
                "body_rate": self.body_rate}


def make_windows(logs: list[FlightLog], horizon: int = HORIZON) -> Windows:
    """Windows at every sample ``i = 0 .. N - horizon - 2`` of each log (the benchmark's
    N - horizon - 1 per run), in the order of ``logs``."""
    parts: dict[str, list] = {k: [] for k in ("p", "v", "q", "w", "u", "run")}
    truth: dict[str, list] = {k: [] for k in QUANTITIES}
    names = []
    steps = np.arange(horizon)
    for index, log in enumerate(logs):
        count = len(log.t) - horizon - 1
        start = np.arange(count)
        names.append(str(log.path))
        parts["p"].append(log.position[start])
        parts["v"].append(log.velocity[start])
        parts["q"].append(log.quat[start])
        parts["w"].append(log.body_rate[start])
        parts["u"].append(log.rotor_speed[start[:, None] + steps])
        parts["run"].append(np.full(count, index))
        later = start[:, None] + steps + 1
        for key, series in zip(QUANTITIES, (log.position, log.velocity, log.quat,
                                             log.body_rate)):
            truth[key].append(series[later])
    cat = {k: np.concatenate(v) for k, v in parts.items()}
    return Windows(cat["p"], cat["v"], cat["q"], cat["w"], cat["u"],
                   {k: np.concatenate(v) for k, v in truth.items()}, cat["run"], tuple(names))


def rotor_delay(log: FlightLog) -> float | None:
    """Delay (s) of the rotor speeds behind the body rate of ``log``, estimated from the log
    itself (module docstring); None when the log does not resolve it. Positive: the rotor
    speeds lag."""
    delays = estimate_delays(log).delays
    if delays["rotor"] is None or delays["gyro"] is None:
        return None
    return float(delays["rotor"] - delays["gyro"])


def align_rotor_speeds(log: FlightLog, delay_s: float | None = None
                       ) -> tuple[FlightLog, float]:
    """``log`` with its rotor speeds shifted earlier by ``delay_s`` (default
    :func:`rotor_delay`; 0 when not resolved): Omega_aligned(t) = Omega(t + delay) by linear
    interpolation, held at the ends, so that every sample -- and every benchmark window --
    is kept. Returns the log and the delay applied (s)."""
    delay = rotor_delay(log) if delay_s is None else float(delay_s)
    if delay is None or delay == 0.0:
        return log, 0.0
    t, speed = log.t, log.rotor_speed
    shifted = np.stack([np.interp(t + delay, t, speed[:, j]) for j in range(speed.shape[1])],
                       axis=1)
    return replace(log, rotor_speed=shifted), delay


def naive_prediction(windows: Windows) -> dict:
    """Hold the state: every step predicts the window's initial state."""
    h = windows.rotor_speed.shape[1]
    return {k: np.repeat(v[:, None], h, axis=1) for k, v in zip(
        QUANTITIES, (windows.position, windows.velocity, windows.quat, windows.body_rate))}


def physics_prediction(windows: Windows) -> dict:
    """The authors' physics baseline (module docstring), batched over all windows."""
    p, v, q, w = windows.position, windows.velocity, quat_normalize(windows.quat), \
        windows.body_rate
    dt = PERIOD
    g = np.array([0.0, 0.0, GRAVITY])
    out: dict[str, list] = {k: [] for k in QUANTITIES}
    for k in range(windows.rotor_speed.shape[1]):
        thrust = np.clip(KT * np.square(windows.rotor_speed[:, k]).sum(1), 0.0,
                         THRUST_TO_WEIGHT * MASS * GRAVITY)
        force = np.zeros_like(p)
        force[:, 2] = thrust

        def accel(quat, force=force):
            return rotate(quat, force) / MASS - g

        a1, d1 = accel(q), quat_derivative(q, w)
        q2 = quat_normalize(q + dt / 2 * d1)
        a2, d2 = accel(q2), quat_derivative(q2, w)
        q3 = quat_normalize(q + dt / 2 * d2)
        a3, d3 = accel(q3), quat_derivative(q3, w)
        q4 = quat_normalize(q + dt * d3)
        a4, d4 = accel(q4), quat_derivative(q4, w)
        v2, v3, v4 = v + dt / 2 * a1, v + dt / 2 * a2, v + dt * a3
        p = p + dt / 6 * (v + 2 * v2 + 2 * v3 + v4)
        v = v + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
        q = quat_normalize(q + dt / 6 * (d1 + 2 * d2 + 2 * d3 + d4))
        for key, value in zip(QUANTITIES, (p, v, q, w)):
            out[key].append(value)
    return {k: np.stack(v, axis=1) for k, v in out.items()}


def _angle(truth: np.ndarray, pred: np.ndarray, published: bool) -> np.ndarray:
    if published:       # xyzw arrays multiplied as wxyz (module docstring)
        a, b = truth[..., [1, 2, 3, 0]], pred[..., [1, 2, 3, 0]]
        d = quat_multiply(quat_conjugate(a), b)
        return 2 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), d[..., 0])
    d = quat_multiply(quat_conjugate(truth), pred)
    return 2 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def _errors(key: str, truth: np.ndarray, pred: np.ndarray, published: bool) -> np.ndarray:
    if key == "R":
        return _angle(truth, pred, published)
    return np.linalg.norm(pred - truth, axis=-1)


def curves(windows: Windows, prediction: dict, protocol: str = "published") -> dict:
    """Mean error per horizon: dict quantity -> (H,) array (units m, m/s, rad, rad/s)."""
    if protocol not in ("published", "per_run"):
        raise ValueError(f"protocol must be 'published' or 'per_run', got {protocol!r}")
    out = {}
    count, horizon = windows.rotor_speed.shape[:2]
    for key in QUANTITIES:
        pred = prediction[key]
        if protocol == "published":
            first = windows.truth[key][:, 0]
            values = []
            for h in range(1, horizon + 1):
                n = count - h + 1
                values.append(_errors(key, first[h - 1:h - 1 + n], pred[:n, h - 1],
                                      True).mean())
            out[key] = np.array(values)
        else:
            err = _errors(key, windows.truth[key], pred, False)        # (B, H)
            runs = np.unique(windows.run)
            out[key] = np.mean([err[windows.run == r].mean(0) for r in runs], axis=0)
    return out


def of_run(windows: Windows, prediction: dict, run: int) -> tuple[Windows, dict]:
    """The windows of run index ``run`` alone (``windows.run == run``, in their order) and
    ``prediction`` (quantity -> (B, H, k)) restricted to them: what :func:`make_windows` and
    the same prediction give for that run's log alone, so that :func:`score` of it is the
    run's own row (each run reported, not only the pooled one)."""
    keep = windows.run == run
    part = Windows(windows.position[keep], windows.velocity[keep], windows.quat[keep],
                   windows.body_rate[keep], windows.rotor_speed[keep],
                   {k: v[keep] for k, v in windows.truth.items()}, windows.run[keep],
                   windows.names)
    return part, {k: prediction[k][keep] for k in QUANTITIES}


def summary(curve: dict) -> dict:
    """[h1, h10, h50, SimErr] per quantity from :func:`curves` (plain floats, for JSON)."""
    return {k: [float(c[h - 1]) for h in REPORTED] + [float(c.sum())]
            for k, c in curve.items()}


def score(windows: Windows, prediction: dict, protocol: str = "published") -> dict:
    """The benchmark's numbers of one prediction: quantity -> [h1, h10, h50, SimErr]."""
    return summary(curves(windows, prediction, protocol))


def rate_skill(windows: Windows, prediction: dict, horizons: tuple[int, ...] = (10, 50)) -> dict:
    """How much of the body-rate change a prediction gets right, per body axis (x, y, z).

    With ``dw = w(h) - w(0)`` the true change over h steps and ``dw_hat`` the predicted one
    (each window against its own truth): ``simerr_model`` / ``simerr_hold`` = sum over h of
    the mean |error| per axis of the prediction and of holding the rate (rad/s);
    ``corr_h{h}`` = correlation of dw_hat and dw over the windows; ``gain_h{h}`` = the
    least-squares scale of dw_hat onto dw, <dw_hat, dw> / <dw_hat, dw_hat>. Scaled by that
    gain, a prediction's mean-square error is (1 - corr^2) times the rate-held one's at best:
    a diagnostic of what a model's rotation can gain, not a model."""
    start = windows.body_rate[:, None]
    true = windows.truth["w"] - start
    pred = prediction["w"] - start
    out = {"simerr_model": np.abs(pred - true).mean(0).sum(0).tolist(),
           "simerr_hold": np.abs(true).mean(0).sum(0).tolist()}
    for h in horizons:
        a, b = pred[:, h - 1], true[:, h - 1]
        a0, b0 = a - a.mean(0), b - b.mean(0)
        out[f"corr_h{h}"] = ((a0 * b0).sum(0) / np.sqrt((a0 * a0).sum(0) * (b0 * b0).sum(0)
                                                        + 1e-300)).tolist()
        out[f"gain_h{h}"] = ((a * b).sum(0) / np.maximum((a * a).sum(0), 1e-300)).tolist()
    return out
