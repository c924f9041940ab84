"""The rotor order behind a verdict: a verdict on a log whose rotor order the torque balance
does not confirm is never stated above ``UNCONFIRMED_MAX_P``, and one whose order is
doubtful is tentative (issue 44).

A log with two rotor columns swapped is read by every explanation as a strange torque
pattern; the evidence then names some effect with high confidence. The checks refuse an
order that another fits far better (:func:`quadsim.logs.checks.check_rotor_order`,
Delta chi^2 > 25), but on real, filtered logs a wrong order is often not that clear: the
status (:func:`quadsim.logs.checks.rotor_order_status`) is *confirmed* (every other order
fits worse by Delta chi^2 > 25), *doubtful* (another order fits better by Delta chi^2 > 4)
or neither (not told apart). Here:

* not confirmed: every probability of the verdict is capped at ``UNCONFIRMED_MAX_P`` = 0.99
  (a wrong order cannot be ruled out at better than the balance's own resolution) and the
  status' note is added;
* doubtful: the verdict, whatever its outcome, is also ``tentative``, with a sentence naming
  the ``--rotor-map`` that fits better.

Example::

    >>> statuses = order_statuses(logs, params)
    >>> verdict = mark(judge(rows, reference, name, cap=probability_cap(statuses)), statuses)
"""

from __future__ import annotations

import dataclasses

from ..logs.checks import RotorOrder, rotor_order_status

__all__ = ["UNCONFIRMED_MAX_P", "cap_decision", "mark", "order_statuses", "probability_cap"]

#: the highest probability stated on a log whose rotor order is not confirmed ("> 99 %" is
#: not said: the order's own evidence is weaker than that).
UNCONFIRMED_MAX_P = 0.99


def order_statuses(logs, params) -> list[RotorOrder]:
    """:func:`quadsim.logs.checks.rotor_order_status` of each log (FlightLogs, cut)."""
    return [rotor_order_status(log, params) for log in logs]


def probability_cap(statuses) -> float:
    """1 when every log's order is confirmed, else ``UNCONFIRMED_MAX_P``."""
    return 1.0 if all(s.confirmed for s in statuses) else UNCONFIRMED_MAX_P


def mark(verdict, statuses):
    """``verdict`` with the statuses' notes (orders not confirmed) and, where an order is
    doubtful, ``tentative`` and a sentence in its answer naming the map that fits better."""
    notes = tuple(s.note for s in statuses if s.note and s.note not in verdict.notes)
    doubtful = [s for s in statuses if s.doubtful]
    if not notes and not doubtful:
        return verdict
    answer = verdict.answer
    tentative = verdict.tentative
    if doubtful:
        maps = ", ".join(sorted({",".join(str(m + 1) for m in s.rival) for s in doubtful}))
        answer += (f" Tentative: the torque balance fits the rotor columns better in another "
                   f"order (--rotor-map {maps}); a wrong rotor order can produce this reading.")
        tentative = verdict.outcome != "refused"
    return dataclasses.replace(verdict, answer=answer, tentative=tentative,
                               notes=verdict.notes + notes)


def cap_decision(decision, cap: float):
    """A held-out :class:`~quadsim.gap.diagnose.Decision` with every probability capped at
    ``cap`` (the ranking kept)."""
    if cap >= 1.0:
        return decision
    ranked = tuple((k, min(p, cap), w) for k, p, w in decision.ranked)
    rows = tuple(dataclasses.replace(r, probability=min(r.probability, cap))
                 if hasattr(r, "probability") else {**r, "probability": min(r["probability"],
                                                                            cap)}
                 for r in decision.rows)
    return dataclasses.replace(decision, ranked=ranked, rows=rows)
