"""The diagnosis on logs without a pose (IMU and motors only): the body-frame balance alone.

The residual wrench (:mod:`quadsim.gap.residual`) needs no pose: the measured force is the
mass times the accelerometer's specific force and the measured torque comes from the gyro
(``I w_dot + w x I w``), both in the body frame; the model's rotor wrench is body-frame too.
What a pose adds is the effects whose loads read the vehicle's motion in the world: the air
velocity (wind, body and rotor drag, blade flapping, translational lift), the height (ground
effect) and the world's directions in the body frame (a payload swinging under gravity).
Each effect declares what it reads (:attr:`quadsim.effects.facts.EffectFacts.needs_pose`);
on a log without a pose those effects are neither shared by the references nor weighed as a
flight's explanation (:func:`needs_pose`), and the answer names them with what would add
them (:func:`missing_words`).

Stand-ins (:func:`posefree_log`): the pose-less log gets position 0, velocity 0 and the
identity attitude, so that the states have the shape every stage expects; no effect weighed
on it reads them (the filter above), and ``FlightStates.pose`` is False.

Example::

    >>> from quadsim.gap.posefree import missing_words, posefree_log
    >>> log = posefree_log(imu_log)            # FlightLog with stand-in pose
    >>> missing_words()                        # "no velocity, height or attitude logged: ..."
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..effects import EFFECTS
from ..effects.facts import POSE_PARTS, without_pose

__all__ = ["missing_words", "needs_pose", "posefree_log"]


def needs_pose(parts) -> bool:
    """Whether any effect of ``parts`` ((effect, fixed, fitted) triples, an explanation's or
    a shared group's) reads the pose (:attr:`~quadsim.effects.facts.EffectFacts.needs_pose`).
    Names that are not library effects (the diagnosis' own fit forms) read none."""
    return any(name in EFFECTS and EFFECTS[name].facts.needs_pose for name, _, _ in parts)


def posefree_log(log):
    """``log`` (a FlightLog without a pose) with the stand-in pose of the module doc:
    position and velocity zero (m, m/s), attitude the identity quaternion."""
    n = len(log.t)
    return dataclasses.replace(log, position=np.zeros((n, 3)), velocity=np.zeros((n, 3)),
                               quat=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))


def missing_words() -> str:
    """One sentence: which pose parts are not logged, the effects not weighed for want of
    them (from the effects' facts), and what would add them."""
    needed = without_pose(EFFECTS)
    parts = [p for p in POSE_PARTS if any(p in v for v in needed.values())]
    names = ", ".join(name.replace("_", " ") for name in needed)
    return (f"no {_listed(parts)} logged: {names} not weighed (the body-frame force and "
            f"torque balance was used); log the state estimate or motion capture (columns "
            f"{'; '.join(POSE_PARTS[p] for p in parts)}) to add them")


def _listed(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " or " + words[-1]


def reference_has_pose(reference) -> bool:
    """Whether a calibrated reference model (:class:`quadsim.gap.calibrate.Reference`) was
    built on logs with a pose: its shared groups include an effect that reads one."""
    return needs_pose(reference.candidate.parts)


def check_same_kind(states, reference, name: str) -> None:
    """InputError when a flight and its references differ in having a pose: the
    references' shared drag and wind would act on the stand-in pose of a flight without
    one, and a flight with one would be weighed on effects the references never shared."""
    from ..core.errors import InputError

    ref_pose = reference_has_pose(reference)
    if bool(getattr(states, "pose", True)) != ref_pose:
        which = ("the reference flights log a pose, this flight does not" if ref_pose else
                 "this flight logs a pose, the reference flights do not")
        raise InputError(f"{name}: x..z, qw..qz: {which}: judge "
                         "logs of one kind together (without a pose: IMU and motors only, "
                         "the body-frame balance; drop the pose columns of the others to "
                         "compare them so)")


def without_pose_note(verdict, log):
    """``verdict`` (:class:`quadsim.gap.result.Verdict`) with :func:`missing_words` at the
    end of its answer and in its notes when ``log`` (a FlightLog) has no pose; else as is."""
    if getattr(log, "has_pose", True) or verdict.outcome == "refused":
        return verdict
    said = missing_words()
    return dataclasses.replace(verdict, answer=f"{verdict.answer} Not weighed: {said}.",
                               notes=tuple(verdict.notes) + (said,))
