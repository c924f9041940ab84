"""What the rerun recording of a gap diagnosis carries (``--rerun OUT.rrd``): the same series
as the report's figures (:mod:`quadsim.gap.plots`).

Per flight with a residual series (per-flight mode: every judged flight; held out: every
held-out flight): its logged motion as a trajectory, and per wrench channel one plot
view with the residual before the answer, after it, and the references' 95 % band
(+-1.96 sigma_c; held out: the floor), on the flight's own time stamps (s) in the channel's
unit (N, N m).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .plots import Z95

__all__ = ["recording"]

_WRENCH = ("Fx", "Fy", "Fz", "Mx", "My", "Mz")


def _bands(result, series) -> np.ndarray | None:
    if series.sigma is not None:
        return np.asarray(series.sigma, float)
    channels = (result.get("verdict") or {}).get("channels") or {}
    if not channels:
        return None
    return np.array([channels[c]["floor"] if c in channels else np.nan
                     for c in series.channels])


def recording(result) -> dict | None:
    """Keyword arguments of :func:`quadsim.viewer.try_save_recording` for ``result`` (a
    :class:`~quadsim.gap.result.Diagnosis`): ``params``, ``trajectories`` (flight name ->
    its logged :class:`~quadsim.vehicle.state.Trajectory`), ``residuals`` ("channel
    flight" -> (t, (N, K) values, labels: before, after, band + and -)), ``title``,
    ``tab``. None when the result holds no series (a result read back from JSON)."""
    from ..vehicle.state import Trajectory

    if result.get("mode") == "per-flight":
        series = [f.series for f in getattr(result, "flights", ())
                  if getattr(f, "series", None) is not None]
    else:
        series = list(getattr(result, "held_series", ()) or ())
        if not series and getattr(result, "series", None) is not None:
            series = [result.series]
    if not series:
        return None
    trajectories, residuals = {}, {}
    for s in series:
        name = Path(str(s.flight)).name
        st = s.states
        if getattr(st, "position", None) is not None and getattr(st, "quat", None) is not None:
            trajectories[name] = Trajectory(st.t, st.position, st.velocity, st.quat,
                                            st.body_rate, st.rotor_speed, engine="log")
        band = _bands(result, s)
        for k, channel in enumerate(s.channels):
            if channel not in _WRENCH:
                continue
            columns = [s.before[:, k], s.after[:, k]]
            labels = ["before", "after"]
            if band is not None and np.isfinite(band[k]):
                half = np.full(len(s.t), Z95 * band[k])
                columns += [half, -half]
                labels += ["band +", "band -"]
            residuals[f"{channel} {name}"] = (np.asarray(s.t, float),
                                              np.stack(columns, axis=1), labels)
    return {"params": series[0].params, "trajectories": trajectories,
            "residuals": residuals, "title": "quadsim gap: residual wrench before and after "
            "the answer", "tab": "residuals"}
