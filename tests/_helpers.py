"""Helpers shared by several test files (not a test module)."""

from __future__ import annotations

from quadsim.effects import make_effect

#: what the generated reference flights of the per-flight tests share: an 8 ms motor lag (s)
#: and rotor drag (kg/rad)
LAG, DRAG = 0.008, 2e-7


def shared_effects(lag: float = LAG, drag: float = DRAG) -> list:
    """The effects every generated reference flight shares (motor lag, rotor drag)."""
    return [make_effect("motor_lag", time_constant=lag),
            make_effect("rotor_drag", coefficient=drag)]


def one_line(capsys, *names: str) -> str:
    """The captured refusal: nothing on stdout, one ``error:`` line naming ``names``."""
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert captured.out == "" and len(err.splitlines()) == 1, err
    assert err.startswith("error: "), err
    for name in names:
        assert name in err, err
    return err
