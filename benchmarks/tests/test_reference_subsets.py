"""benchmarks.reference_subsets: its draws and its score, on a result written by hand."""

from benchmarks.reference_subsets import score, subset

LABELS = {"flights": {"p1.csv.gz": {"label": "payload"}, "p2.csv.gz": {"label": "payload"},
                      "n1.csv.gz": {"label": "none"}, "n2.csv.gz": {"label": "none"},
                      "n3.csv.gz": {"label": "none"}}}


def _flight(name, outcome, verdict, tentative=False, **params):
    return {"file": f"mixed/{name}", "outcome": outcome, "verdict": verdict,
            "probability": 0.9, "tentative": tentative, "params": params}


def test_subsets_are_the_same_every_run_and_of_distinct_flights():
    """Draw d of size k is random.Random(100 d + k)'s: sorted, distinct, within 0..19."""
    assert subset(3, 1) == subset(3, 1)
    for k in (3, 5, 10):
        for d in (1, 2, 3, 4):
            picked = subset(k, d)
            assert len(set(picked)) == k and picked == sorted(picked)
            assert all(0 <= i < 20 for i in picked)
    assert subset(3, 1) != subset(3, 2)


def test_the_score_counts_payloads_plain_flights_and_confident_false_alarms():
    """A payload is right as a mass within 2 g of +7.4 g (+6.5 g yes, +3 g no); a plain flight
    right only as no_significant_gap; a name on a plain flight is confident unless
    tentative, and 'unexplained' is no name."""
    result = {"flights": [
        _flight("p1.csv.gz", "effect", "cable_payload+mass_offset",
                **{"cable_payload.mass": 0.0045, "mass_offset.mass": 0.002}),
        _flight("p2.csv.gz", "effect", "mass_offset", **{"mass_offset.mass": 0.003}),
        _flight("n1.csv.gz", "no_significant_gap", "no_significant_gap"),
        _flight("n2.csv.gz", "effect", "signal_delay", tentative=True),
        _flight("n3.csv.gz", "effect", "signal_delay"),
    ]}
    row = score(result, LABELS)
    assert row["payload"] == [1, 2] and row["plain"] == [1, 3]
    assert row["plain_confident"] == 1
    assert row["plain_names"] == {"signal_delay (tentative)": 1, "signal_delay": 1}
    result["flights"][4] = _flight("n3.csv.gz", "unexplained", "unexplained")
    row = score(result, LABELS)
    assert row["plain_confident"] == 0 and row["plain_names"]["unexplained"] == 1


def test_cut_log_keeps_the_columns_a_user_may_have(tmp_path):
    """``commands`` drops the rotor speeds, ``imu`` keeps t, gyro, accelerometer, commands and
    vbat; the values are the same strings, and the same cut gives the same bytes."""
    import gzip

    from benchmarks.reference_subsets import KEPT, cut_log

    src = tmp_path / "f.csv.gz"
    head = "t,x,qw,wx,wy,wz,ax,ay,az,rotor_1,cmd_1,vbat"
    with gzip.open(src, "wt") as handle:
        handle.write(head + "\n0,1.5,1,0.1,0.2,0.3,0,0,9.81,1500,0.42,3.9\n")
    commands = cut_log(src, KEPT["commands"], tmp_path / "c.csv.gz")
    imu = cut_log(src, KEPT["imu"], tmp_path / "i.csv.gz")
    assert gzip.open(commands, "rt").read().split("\n")[:2] == [
        "t,x,qw,wx,wy,wz,ax,ay,az,cmd_1,vbat", "0,1.5,1,0.1,0.2,0.3,0,0,9.81,0.42,3.9"]
    assert gzip.open(imu, "rt").read().split("\n")[:2] == [
        "t,wx,wy,wz,ax,ay,az,cmd_1,vbat", "0,0.1,0.2,0.3,0,0,9.81,0.42,3.9"]
    again = cut_log(src, KEPT["imu"], tmp_path / "i2.csv.gz")
    assert again.read_bytes() == imu.read_bytes()
