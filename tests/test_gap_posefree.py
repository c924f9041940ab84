"""``gap`` on logs without a pose (issue 44, item 1): IMU (accelerometer, gyro) and rotors
only. The body-frame force and torque balance needs no pose; the effects that read one
(declared by each effect: ``EffectFacts.needs_pose``) are neither shared by the references
nor weighed, and the answer names them with what would add them.

Generated closed-loop flights (quadsim.logs.generate, MuJoCo, sensor noise) with their
position, attitude and velocity columns dropped: 4 nominal references; a nominal flight is
clear, a 4 g mass offset (+10.8 % of 37 g) is stated with its size (named, or beside the thrust
curve it cannot be told from without a pose)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from quadsim.core.errors import QuadsimWarning
from quadsim.effects import EFFECTS, EffectSet, make_effect
from quadsim.effects.facts import without_pose
from quadsim.gap.calibrate import calibrate
from quadsim.gap.diagnose import judge_one, prepare
from quadsim.gap.logcheck import missing_words
from quadsim.logs.checks import check_logs
from quadsim.logs.generate import generate_flight
from quadsim.vehicle.params import load_params

from _helpers import posefree_noise

NOISE = posefree_noise()
PATHS = ("figure8", "steps", "lissajous", "figure8")

pytestmark = pytest.mark.xdist_group("test_gap_posefree")


def _imu(log):
    return dataclasses.replace(log, position=None, quat=None, velocity=None)


def _fly(cf, effects, seed, path="figure8"):
    log, _ = generate_flight(cf, path, EffectSet(tuple(effects)), NOISE, seed, duration=5.0,
                             speed=1.0)
    return check_logs([_imu(log)], cf)[0][0]


@pytest.fixture(scope="module")
def cf():
    return load_params("crazyflie21")


@pytest.fixture(scope="module")
def reference(cf):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [_fly(cf, (), seed, path) for seed, path in enumerate(PATHS)]
        return calibrate(prepare(refs, cf), cf)


def test_the_effects_that_read_the_pose_are_declared():
    """From the physics: the air velocity (drag, wind, flapping, lift), the height (ground
    effect); none of the body-frame effects, and not a payload's swing (it reads the
    effective gravity at its mount, which the IMU measures: tests/test_imu_swing.py)."""
    assert set(without_pose(EFFECTS)) == {"wind", "body_drag", "rotor_drag", "blade_flapping",
                                          "translational_lift", "ground_effect"}
    assert without_pose(EFFECTS)["ground_effect"][0] == "height"


def test_references_share_no_effect_that_reads_the_pose(reference):
    shared = {name for name, _, _ in reference.candidate.parts}
    assert not shared & set(without_pose(EFFECTS))
    assert {"nominal_refit", "inertia_error", "motor_lag"} <= shared


def test_nominal_is_clear_and_a_mass_offset_is_named(cf, reference):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        calm = judge_one(_fly(cf, (), 11), reference)
        heavy = judge_one(_fly(cf, (make_effect("mass_offset", mass=0.004),), 11), reference)
    assert calm.outcome == "no_significant_gap", calm.answer
    # without a pose a heavier vehicle and a weaker thrust curve both read as the thrust it
    # needs (Fz alone; c41b28b: mass 49 %, thrust curve 48 %; today 30 / 67 %): the mass is
    # a stated reading at its size, and a thrust-curve lead is tentative, the mass beside it
    assert heavy.outcome == "effect" and "mass_offset" in heavy.readings, heavy.answer
    assert heavy.name == "mass_offset" or (heavy.tentative and "mass_offset" in heavy.answer)
    reading = next(r for r in heavy.posterior if r.name == "mass_offset")
    assert reading.probability >= 0.1
    mass, ci = reading.params["mass_offset.mass"], reading.ci["mass_offset.mass"]
    assert abs(mass - 0.004) < max(ci, 0.0005), (mass, ci)
    for verdict in (calm, heavy):
        assert verdict.answer.endswith(f"Not weighed: {missing_words()}.")
        assert "wind" in missing_words() and "log the state estimate" in missing_words()
    # no reading of an effect that needs the pose was weighed
    assert not {r.name for r in heavy.posterior} & set(without_pose(EFFECTS))


def test_a_flight_with_a_pose_is_not_judged_against_references_without(cf, reference):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        log, _ = generate_flight(cf, "figure8", EffectSet(()), NOISE, 12, duration=5.0)
        verdict = judge_one(check_logs([log], cf)[0][0], reference)
    assert verdict.outcome == "refused"
    assert "this flight logs a pose, the reference flights do not" in verdict.reason


def test_every_flight_refused_while_judged_is_one_line_and_exit_2(cf, tmp_path, capsys):
    """``gap --per-flight`` whose every flight is refused while judged (here: a pose on the
    flights, none on the references): the first reason and how many more, one error line
    (after the loader's warnings on the references), exit 2, no JSON written."""
    from quadsim.gap.__main__ import main
    from quadsim.logs.flightlog import write_log

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        refs = [write_log(tmp_path / f"r{k}.csv.gz",
                          _imu(generate_flight(cf, "figure8", EffectSet(()), NOISE, 30 + k,
                                               duration=3.0)[0])) for k in range(2)]
        posed = [write_log(tmp_path / f"p{k}.csv.gz",
                           generate_flight(cf, "figure8", EffectSet(()), NOISE, 40 + k,
                                           duration=3.0)[0]) for k in range(2)]
    out = tmp_path / "out.json"
    assert main(["--model", "crazyflie21", "--per-flight", *map(str, posed), "--reference",
                 *map(str, refs), "--effects", "mass_offset", "--workers", "1", "--no-cache",
                 "--quiet", "--json", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()      # the loader's warnings first
    errors = [line for line in err if line.startswith("error:")]
    assert len(errors) == 1 and errors[0] == err[-1], err
    assert err[-1].startswith(f"error: {posed[0]}: x..z, qw..qz: this flight logs a pose, the "
                              "reference flights do not")
    assert err[-1].endswith("(and 1 more flight(s) refused: p1.csv.gz)")
    assert not out.exists()


def test_held_out_weighs_no_effect_that_reads_the_pose(cf):
    """The held-out diagnosis on three IMU-only flights with a 4 g mass offset: the weight is
    read (as the mass or as the thrust per Omega^2 that carries it: -9.8 % is 1 / 1.108), no
    explanation that needs the pose is fitted, and the answer says what was not weighed."""
    from quadsim.gap.diagnose import diagnose

    heavy = (make_effect("mass_offset", mass=0.004),)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        logs = [_fly(cf, heavy, seed, path) for seed, path in enumerate(PATHS[:3])]
        result = diagnose(logs, cf)
    weighed = {e["name"] if isinstance(e, dict) else e.name for e in result.effects}
    assert not weighed & set(without_pose(EFFECTS)) and "mass_offset" in weighed
    assert result.verdict.name in ("mass_offset", "nominal_refit", "thrust_factor")
    assert result.verdict.answer.endswith(f"Not weighed: {missing_words()}.")


def test_without_a_pose_what_stays_is_not_said_to_be_outside_the_library():
    """An ``unexplained`` answer on a log without a pose: the effects that read the pose were
    not weighed, so what stays is "not explained by the readings weighed" (per flight and
    held out), and may be one of them; the outcome is unchanged; a named answer only gains
    the sentence; a log with a pose is left as it is."""
    from types import SimpleNamespace

    from quadsim.gap.logcheck import without_pose_note
    from quadsim.gap.result import Verdict

    posefree, posed = SimpleNamespace(has_pose=False), SimpleNamespace(has_pose=True)
    for opening in ("Not in the library:", "Unexplained:"):
        verdict = Verdict("unexplained", "unexplained",
                          f"{opening} after the most probable reading (thrust_factor) the "
                          "residual stays beyond the reference flights' on Fz at 3x.")
        noted = without_pose_note(verdict, posefree)
        assert noted.outcome == "unexplained" and noted.name == "unexplained"
        assert noted.answer.startswith("Not explained by the readings weighed: after the")
        assert opening not in noted.answer
        assert noted.answer.endswith(f"Not weighed: {missing_words()}; what stays may be "
                                     "one of them.")
        assert without_pose_note(verdict, posed) is verdict
    named = Verdict("effect", "mass_offset", "mass_offset (90 %): +4 g heavier.")
    assert without_pose_note(named, posefree).answer == \
        f"mass_offset (90 %): +4 g heavier. Not weighed: {missing_words()}."


def test_without_a_pose_a_declared_confusable_reading_is_stated_beside_the_name():
    """A name on a log without a pose gets each reading its effect and the name's declare
    confusable (``EffectFacts.separate_from``), not stated beside it already, stated with its
    magnitude and how to tell them apart; the name is then tentative. Readings that are not
    such a pair, or a log with a pose, change nothing."""
    from types import SimpleNamespace

    from quadsim.gap.logcheck import confusable, without_pose_note
    from quadsim.gap.result import Reading, Verdict

    hint = EFFECTS["mass_offset"].facts.separate_from["thrust_factor"]
    assert confusable("thrust_factor", "mass_offset") == hint          # declared on one side
    assert confusable("mass_offset", "thrust_factor") == hint
    assert confusable("cable_payload+mass_offset", "thrust_factor") == \
        EFFECTS["thrust_factor"].facts.separate_from["cable_payload"]   # a pair: its first part
    assert confusable("thrust_factor", "wind") == ""
    posterior = (Reading("thrust_factor", 0.87, "-16 % thrust per Omega^2", -1.0),
                 Reading("mass_offset", 0.002, "+7.1 g heavier", -7.0),
                 Reading("wind", 0.001, "a steady air force", -8.0),
                 Reading("no_difference", 0.0, "no difference", -20.0))
    named = Verdict("effect", "thrust_factor", "thrust_factor (87 %): -16 %.", 0.87,
                    posterior=posterior, readings=("thrust_factor",))
    noted = without_pose_note(named, SimpleNamespace(has_pose=False))
    assert noted.tentative and noted.readings == ("thrust_factor", "mass_offset")
    assert noted.confusable_with == ("mass_offset",) and noted.separate_by == {
        "mass_offset": hint}
    assert ("Without a pose it is not told from mass_offset (+7.1 g heavier; 0.2 % here; to "
            f"tell them apart: {hint})") in noted.answer
    assert noted.answer.endswith(f"Not weighed: {missing_words()}.")
    assert (noted.outcome, noted.name, noted.probability) == ("effect", "thrust_factor", 0.87)
    assert without_pose_note(named, SimpleNamespace(has_pose=True)) is named


def test_with_a_pose_a_declared_confusable_reading_within_the_margin_is_stated():
    """With a pose the same pair is stated only where the name's log evidence exceeds the
    rival's by less than SEPARATED (ln 150: "very strong" evidence); beyond it, or for a
    reading no effect declares confusable, or an outcome that names nothing, the verdict is
    returned as it was. A log without a pose is without_pose_note's (returned as is here)."""
    from types import SimpleNamespace

    from quadsim.gap.logcheck import SEPARATED, confusable_note
    from quadsim.gap.result import Reading, Verdict

    assert SEPARATED == pytest.approx(np.log(150.0))
    hint = EFFECTS["mass_offset"].facts.separate_from["thrust_factor"]
    pose = SimpleNamespace(has_pose=True)

    def verdict(mass_log_z, outcome="effect"):
        posterior = (Reading("thrust_factor", 0.96, "-10 % thrust per Omega^2", -173.3),
                     Reading("mass_offset", 0.018, "+4.2 g heavier", mass_log_z),
                     Reading("wind", 0.01, "a steady air force", -174.0),
                     Reading("no_difference", 0.0, "no difference", -337.3))
        return Verdict(outcome, "thrust_factor" if outcome == "effect" else outcome,
                       "thrust_factor (96 %): -10 %.", 0.96, posterior=posterior,
                       readings=("thrust_factor",) if outcome == "effect" else ())

    near = verdict(-173.3 - (SEPARATED - 0.1))
    noted = confusable_note(near, pose)
    assert noted.tentative and noted.readings == ("thrust_factor", "mass_offset")
    assert noted.confusable_with == ("mass_offset",)
    assert noted.separate_by == {"mass_offset": hint}
    assert (f"Tentative: not told apart from mass_offset (+4.2 g heavier; 1.8 % here; to tell "
            f"them apart: {hint}): the library names the pair") in noted.answer
    assert (noted.outcome, noted.name, noted.probability) == ("effect", "thrust_factor", 0.96)
    far = verdict(-173.3 - (SEPARATED + 0.1))
    assert confusable_note(far, pose) is far
    plain = verdict(-173.5, outcome="unexplained")
    assert confusable_note(plain, pose) is plain
    assert confusable_note(near, SimpleNamespace(has_pose=False)) is near


def test_the_margin_is_read_over_the_leads_dispersion():
    """overdispersion: the mean over channels of the reading's mean square over the
    references' typical, floored at 1 (QAIC's c-hat). A pair told apart by 1.5 SEPARATED on a
    flight the noise model holds (dispersion 1) is not where the lead leaves twice the
    references' mean square (dispersion 2: 0.75 SEPARATED in quasi-likelihood units), and
    the answer says by what factor."""
    from types import SimpleNamespace

    from quadsim.gap.judge import overdispersion
    from quadsim.gap.logcheck import SEPARATED, confusable_note
    from quadsim.gap.result import Reading, Verdict

    assert overdispersion([2.0, 4.0, 0.5], [1.0, 2.0, 1.0]) == pytest.approx(1.5)
    assert overdispersion([0.5, 0.9], [1.0, 1.0]) == 1.0
    assert overdispersion([[3.0, 1.0], [1.0, 3.0]], [1.0, 1.0]) == pytest.approx(2.0)
    posterior = (Reading("mass_offset", 0.99, "+1.4 g heavier, off the centre", -100.0),
                 Reading("thrust_mismatch", 0.005, "rotor 1 -5 %", -100.0 - 1.5 * SEPARATED))
    held = Verdict("effect", "mass_offset", "mass_offset (99 %): +1.4 g.", 0.99,
                   posterior=posterior, readings=("mass_offset",))
    pose = SimpleNamespace(has_pose=True)
    assert confusable_note(held, pose) is held
    loose = dataclasses.replace(held, dispersion=2.0)
    noted = confusable_note(loose, pose)
    assert noted.tentative and "thrust_mismatch" in noted.readings
    assert noted.answer.endswith("very strong evidence needs, times 2: the flight's residual "
                                 "after the name is 2x the references' in mean square, which "
                                 "the evidence's noise model does not hold.")


def test_a_margin_from_where_the_priors_centre_the_values_does_not_separate_a_pair():
    """A pair that gives the same force told apart only by the prior's location term
    (Reading.prior_pull = 1/2 |z|^2 at the MAP): l2f's X500 with every propeller 11.7 %
    weaker read +266 g at 0.996, 5.56 log units ahead of `thrust_factor`, which sat far out in
    its narrow prior. Counted at their priors' centres the two lie within SEPARATED: the
    rival is stated, the name tentative, and the words say why; where the data themselves
    separate them (the margin beyond SEPARATED with the pulls counted too) nothing changes."""
    from types import SimpleNamespace

    from quadsim.gap.logcheck import SEPARATED, confusable_note
    from quadsim.gap.result import Reading, Verdict

    pose = SimpleNamespace(has_pose=True)

    def verdict(thrust_pull):
        posterior = (Reading("mass_offset", 0.996, "+266 g heavier", -311.48, prior_pull=0.02),
                     Reading("thrust_factor", 0.004, "-11.7 % thrust per Omega^2",
                             -311.48 - 5.56, prior_pull=thrust_pull))
        return Verdict("effect", "mass_offset", "mass_offset (100 %): +266 g.", 0.996,
                       posterior=posterior, readings=("mass_offset",))

    assert 5.56 > SEPARATED
    apart = verdict(0.0)
    assert confusable_note(apart, pose) is apart
    held = verdict(2.7)
    noted = confusable_note(held, pose)
    assert noted.tentative and noted.readings == ("mass_offset", "thrust_factor")
    assert noted.confusable_with == ("thrust_factor",)
    assert noted.answer.endswith("very strong evidence needs once each value is counted at "
                                 "its prior's centre (where the priors centre the values is no "
                                 "evidence of this flight).")
    assert (noted.outcome, noted.name, noted.probability) == ("effect", "mass_offset", 0.996)
    edge = verdict(5.56 - SEPARATED + 0.02 - 0.01)     # flat margin just above SEPARATED
    assert confusable_note(edge, pose) is edge



def test_without_a_pose_only_the_regimes_the_imu_shows_are_read(cf):
    """regime_masks on a log without a pose: aggressive rotation from the gyro and the
    battery's low part, none of the regimes that read the stand-in position and velocity
    of zero (every sample would be near the ground and hovering)."""
    from quadsim.gap.judge import regime_masks

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", QuadsimWarning)
        log, _ = generate_flight(cf, "figure8", EffectSet(()), NOISE, 3, duration=5.0,
                                 speed=1.0)
        posed = prepare(check_logs([log], cf)[0], cf)[0].fit
        bare = prepare(check_logs([dataclasses.replace(log, position=None, velocity=None,
                                                       quat=None)], cf)[0], cf)[0].fit
    with_pose, without = regime_masks(posed, cf), regime_masks(bare, cf)
    assert {"near_ground", "hover", "fast_forward"} <= set(with_pose)
    assert set(without) == {"aggressive_rotation", "low_battery"}
    np.testing.assert_array_equal(without["aggressive_rotation"],
                                  np.linalg.norm(bare.body_rate, axis=1) > 2.0)
