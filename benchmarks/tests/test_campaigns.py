"""benchmarks.campaigns: the campaigns as data, and the scoring of a verdict's JSON entry."""

from __future__ import annotations

from benchmarks.campaigns import CAMPAIGNS, Flight, score


def test_every_campaign_has_ten_references_and_calm_flights():
    for campaign in CAMPAIGNS.values():
        assert len(campaign.references) == 10
        assert all(f.truth is None and not f.effects for f in campaign.references)
        assert sum(f.truth is None for f in campaign.flights) == 3
        names = [f.name for f in campaign.references + campaign.flights]
        assert len(set(names)) == len(names)


def test_score():
    calm = Flight("calm", 1, "steps", 0.3)
    mass = Flight("mass", 2, "steps", 0.3, (("mass_offset", {"mass": 0.003}),), "mass")
    assert score(calm, {"verdict": "no_significant_gap", "probability": 0.6}) == "right"
    assert score(calm, {"verdict": "wind", "probability": 0.95}) == "confident wrong"
    assert score(calm, {"verdict": "wind", "probability": 0.95, "tentative": True}) == "miss"
    assert score(calm, {"verdict": "unexplained", "probability": 0.99}) == "miss"
    assert score(mass, {"verdict": "cable_payload+mass_offset", "probability": 0.7}) == "named"
    assert score(mass, {"verdict": "thrust_factor", "probability": 0.96, "tentative": True,
                        "readings": ["thrust_factor"],
                        "confusable_with": ["mass_offset"]}) == "stated"
    assert score(mass, {"verdict": "thrust_factor", "probability": 0.99,
                        "readings": ["thrust_factor"]}) == "confident wrong"
    assert score(mass, {"verdict": "thrust_factor", "probability": 0.6,
                        "readings": ["thrust_factor"]}) == "miss"
