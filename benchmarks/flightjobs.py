"""A flight's job as the simulator sources built from one set of SI parameters make it
(:mod:`.multirotor_source`, :mod:`.l2f_source`): the case-side rigid-body and rotor changes,
the loads a source adds, and flying a batch of jobs in worker processes (:func:`fly_all`).

A case's ``effects`` (SI): ``mass`` (kg added at the CoM), ``inertia`` (relative change of
Ixx, Iyy, Izz), ``com`` (x, y m: the CoM moved against the rotors), ``payload`` (kg, x, y, z
m: a point mass; mass, CoM and the full inertia matrix change together, parallel axes about
the new CoM), ``thrust_scale`` (relative change of every rotor's thrust coefficients),
``weak_rotor`` (rotor 1..R, relative change of its own), ``wind`` (m/s world x, y); the
disturbances a source adds on top of its simulator (:func:`disturbances`): ``rate_damping``
(N m s/rad on x, y, z, or one number for all), ``torque`` (N m body x, y, z amplitude) at
``torque_hz``, ``force`` (N body z amplitude) at ``force_hz``.

Example::

    >>> mass, com, inertia = mass_properties({"payload": (0.3, 0.04, 0.0, -0.03)}, 2.0,
    ...                                      (0.02, 0.02, 0.04))
    >>> rotor_scales({"weak_rotor": (2, -0.1)})          # array([1. , 0.9, 1. , 1. ])
"""

from __future__ import annotations

import os

import numpy as np

__all__ = ["disturbances", "fly_all", "mass_properties", "rotor_scales", "wind_vector"]


def mass_properties(effects: dict, mass: float, inertia) -> tuple[float, np.ndarray,
                                                                  np.ndarray]:
    """(mass kg, CoM (3,) m body, inertia (3, 3) kg m^2 about the CoM) of the nominal
    ``mass`` and principal ``inertia`` (3,) with the case's ``effects`` (module doc)."""
    e = effects
    mass = mass + float(e.get("mass", 0.0))
    inertia = np.diag(np.asarray(inertia) * (1.0 + np.asarray(e.get("inertia", (0, 0, 0)),
                                                              dtype=float)))
    com = np.zeros(3)
    com[:2] = e.get("com", (0.0, 0.0))
    if "payload" in e:        # point mass m_p at r_p (body): parallel axes about the new CoM
        m_p, r_p = float(e["payload"][0]), np.asarray(e["payload"][1:], dtype=float)
        c = com + m_p * r_p / (mass + m_p)
        inertia = (inertia + mass * (c @ c * np.eye(3) - np.outer(c, c))
                   + m_p * ((r_p - c) @ (r_p - c) * np.eye(3) - np.outer(r_p - c, r_p - c)))
        mass, com = mass + m_p, c
    return mass, com, inertia


def rotor_scales(effects: dict, rotors: int = 4) -> np.ndarray:
    """(R,) factor on each rotor's thrust coefficients: ``thrust_scale`` on all,
    ``weak_rotor`` on its own."""
    scale = np.full(rotors, 1.0 + float(effects.get("thrust_scale", 0.0)))
    if "weak_rotor" in effects:
        scale[int(effects["weak_rotor"][0]) - 1] *= 1.0 + float(effects["weak_rotor"][1])
    return scale


def wind_vector(effects: dict) -> np.ndarray:
    """(3,) world wind (m/s), horizontal."""
    wind = np.zeros(3)
    wind[:2] = effects.get("wind", (0.0, 0.0))
    return wind


def disturbances(effects: dict) -> dict:
    """The added loads of a case (module doc) as the job fields the sources read: wind (3,),
    rate_damping (3,), torque (3,), torque_hz, force, force_hz (SI; zeros where absent)."""
    e = effects
    return {"rate_damping": np.broadcast_to(np.asarray(e.get("rate_damping", 0.0), float),
                                            (3,)).copy(),
            "wind": wind_vector(e), "torque": np.asarray(e.get("torque", (0.0, 0.0, 0.0)),
                                                         dtype=float),
            "torque_hz": float(e.get("torque_hz", 0.0)), "force": float(e.get("force", 0.0)),
            "force_hz": float(e.get("force_hz", 0.0))}


def fly_all(fly, to_log, specs: list, jobs: list, *, source: str, model: str,
            rates: tuple[int, int], workers: int | None = None) -> list[tuple]:
    """``(log, truth)`` per spec: ``fly((spec, job))`` in ``workers`` spawned processes
    (default: the CPU count, at most 4; one: in this process), in order; the log
    ``to_log(raw, spec, job["com"])``; the truth sidecar names the ``source``, its ``model``,
    the seed, speed, duration, the (physics, log) ``rates`` in Hz, the case-side effects and
    the job as ``<source>_params``."""
    from .simlog import jsonable

    workers = min(len(specs), workers or min(4, os.cpu_count() or 1))
    if workers > 1:
        import multiprocessing

        with multiprocessing.get_context("spawn").Pool(workers) as pool:
            raws = pool.map(fly, list(zip(specs, jobs)), chunksize=1)
    else:
        raws = [fly(a) for a in zip(specs, jobs)]
    return [(to_log(raw, spec, job["com"]),
             {"source": source, "model": model, "seed": spec.seed, "speed": spec.speed,
              "duration_s": spec.duration, "physics_hz": rates[0], "log_hz": rates[1],
              "effects": jsonable(spec.effects), f"{source}_params": jsonable(job)})
            for spec, job, raw in zip(specs, jobs, raws)]
