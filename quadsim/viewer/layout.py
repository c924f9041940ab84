"""The recording's default rerun blueprint (3D view left; tabs of plot grids right) and its
camera. Part of :mod:`quadsim.viewer`."""

from __future__ import annotations

import numpy as np

from ..core.errors import InputError
from ..vehicle.state import STATE12_NAMES, STATE12_UNITS
from .series import TIMELINE


def _plot(rrb, origin: str, name: str, first: bool):
    """A time-series view; only the first of a grid shows its legend (colours repeat)."""
    legend = rrb.PlotLegend(corner="RightBottom", visible=first)
    return rrb.TimeSeriesView(origin=origin, name=name, plot_legend=legend)


def _rotor_views(rrb, rotor_count: int, normalised: bool) -> list:
    views = []
    for i in range(1, rotor_count + 1):
        views += [_plot(rrb, f"rotors/speed_{i}", f"rotor {i} speed (rad/s)", i == 1),
                  _plot(rrb, f"rotors/command_{i}", f"rotor {i} command (rad/s)", i == 1),
                  _plot(rrb, f"rotors/thrust_{i}", f"rotor {i} thrust b Omega^2 (N)", i == 1)]
        if normalised:
            views.append(_plot(rrb, f"rotors/command_norm_{i}", f"rotor {i} command (0-1)",
                               i == 1))
    return views


def default_blueprint(rrb, rotor_count: int, residual_names: list[str], title: str, *,
               normalised: bool = False, tab: str = "states", camera=None):
    """3D view on the left; tabs of plot grids (states, rotors, residuals) on the right.

    ``camera``: (eye position, look target) in the world frame (m), or None for rerun's."""
    units = dict(zip(STATE12_NAMES, STATE12_UNITS))
    state_views = [_plot(rrb, f"states/{n}", f"{n} ({units[n]})", k == 0)
                   for k, n in enumerate(STATE12_NAMES)]
    tabs = [rrb.Grid(*state_views, grid_columns=3, name="states"),
            rrb.Grid(*_rotor_views(rrb, rotor_count, normalised),
                     grid_columns=4 if normalised else 3, name="rotors")]
    if residual_names:
        residual_views = [_plot(rrb, f"residuals/{n}", f"{n} model - measured ({units[n]})"
                                if n in units else n, k == 0)
                          for k, n in enumerate(residual_names)]
        tabs.append(rrb.Grid(*residual_views, grid_columns=3, name="residuals"))
    names = [t.name for t in tabs]
    if tab not in names:
        raise InputError(f"plot tab {tab!r} not in this recording; valid: {', '.join(names)}")
    eye = None
    if camera is not None:
        eye = rrb.EyeControls3D(position=camera[0], look_target=camera[1], eye_up=[0, 0, 1])
    scene = rrb.Spatial3DView(origin="world", name=title or "vehicle", eye_controls=eye,
                              line_grid=rrb.LineGrid3D(visible=True, spacing=0.25))
    return rrb.Blueprint(rrb.Horizontal(scene, rrb.Tabs(*tabs, active_tab=names.index(tab)),
                                        column_shares=[2, 3]),
                         rrb.TimePanel(timeline=TIMELINE, state="collapsed"),
                         collapse_panels=True)


def camera_pose(members) -> tuple[np.ndarray, np.ndarray]:
    """Eye and target that frame every path: look at the paths' centre from the front-left,
    above, at a distance that grows with the paths' extent."""
    points = np.concatenate([np.asarray(m.position, float) for _, m in members])
    points = points[np.all(np.isfinite(points), axis=1)]
    low, high = points.min(0), points.max(0)
    target = 0.5 * (low + high)
    distance = max(1.5, 1.8 * float(np.linalg.norm(high - low)))
    return target + distance * np.array([-0.55, -0.75, 0.45]), target


