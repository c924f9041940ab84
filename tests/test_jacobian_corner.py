"""The shared parameters' Jacobian (quadsim.gap.reference.jacobian) at a corner of the
allowed set: a value at its upper bound whose step down crosses the physical set's wall is
pinned both ways, a zero column (it was: a step past the bound, and the flight refused)."""

from __future__ import annotations

import importlib
from types import SimpleNamespace

import numpy as np

from quadsim.effects.base import EffectSet
from quadsim.gap.fitting import Candidate
from quadsim.vehicle.params import load_params

ref_mod = importlib.import_module("quadsim.gap.reference")


def test_a_value_pinned_by_its_bound_and_the_wall_is_a_zero_column(monkeypatch):
    cf = load_params("crazyflie21")         # Ixx = Iyy = 2.05e-5, Izz = 3.05e-5 kg m^2
    cand = Candidate("reference", (("inertia_error", {}, ("xx", "yy", "zz")),))

    def residual(states, reference, effects, memo=None):
        # the rigid body's principal moments: ModelError where they break the triangle
        return np.diag(EffectSet(tuple(effects)).apply_to_params(cf).inertia).copy()

    monkeypatch.setattr(ref_mod, "weighted_residual", residual)
    # zz and yy at their +200 % bound (Izz 9.15e-5, Iyy 6.15e-5), xx where Ixx + Iyy = Izz
    # (Ixx 3.0e-5): yy can move neither way
    xx = 9.15e-5 / 2.05e-5 - 3.0 - 1.0
    reference = SimpleNamespace(candidate=cand, params=cf, theta=np.array([xx, 2.0, 2.0]))
    jac = ref_mod.jacobian(None, reference, [0, 1, 2], cand.effects)
    assert np.all(jac[:, 1] == 0.0)
    # xx steps up (free), zz at its bound steps down (allowed: Izz falls): the other columns
    # are the moments' own derivatives, d I_ii / d theta_ii = I_ii nominal
    assert abs(jac[0, 0] - 2.05e-5) < 1e-9
    assert abs(jac[2, 2] - 3.05e-5) < 1e-9 and np.all(jac[[0, 1], 2] == 0.0)
