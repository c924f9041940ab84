"""Command-only diagnosis on the real Crazyflie flights: per-flight verdicts on the mixed
flights with measured rotor speeds vs with the speed columns removed and synthesised from
the commands (model fitted on the nominal flights), every log checked as ``gap`` checks it
(:func:`quadsim.logs.checks.check_logs`). Prints agreement and the pairs.

    python scripts/command_only_check.py [DATA_DIR] [--json OUT.json]

DATA_DIR: the shared data folder (default ../shared/data beside the checkout); a folder
without the Crazyflie flights is refused in one line (exit 2).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # run from a checkout

from quadsim.core.errors import InputError, run_cli  # noqa: E402
from quadsim.gap import diagnose_per_flight  # noqa: E402
from quadsim.gap.logcheck import fit_command_model, synthesise_speeds, without_speeds  # noqa: E402
from quadsim.logs.checks import check_logs  # noqa: E402
from quadsim.logs.flightlog import load_log  # noqa: E402
from quadsim.vehicle.params import load_params  # noqa: E402

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _flights(data: Path, folder: str) -> list[Path]:
    """The ``*.csv.gz`` flights of ``data/crazyflie21_brushless/folder``; InputError naming
    the folder when there are none."""
    paths = sorted((data / "crazyflie21_brushless" / folder).glob("*.csv.gz"))
    if not paths:
        raise InputError(f"{data}: crazyflie21_brushless/{folder}/*.csv.gz: no flights found "
                         "(give the shared data folder as DATA_DIR)")
    return paths


@run_cli
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("data", nargs="?", type=Path, default=DEFAULT_DATA, metavar="DATA_DIR",
                        help="the shared data folder (default: ../shared/data)")
    parser.add_argument("--json", metavar="OUT.json", help="write the pairs and the verdicts")
    args = parser.parse_args(argv)
    nominal_paths, mixed_paths = _flights(args.data, "nominal"), _flights(args.data, "mixed")
    params = load_params("crazyflie21")
    # the logs as gap reads them: checked, ground spans cut, a rotor speed at a pulse-count
    # factor read back (quadsim.logs.checks.check_logs)
    nominal = check_logs([load_log(p, warn=False) for p in nominal_paths], params)[0]
    mixed = check_logs([load_log(p, warn=False) for p in mixed_paths], params)[0]
    model = fit_command_model(nominal)
    print(f"command model: tau {model.tau * 1e3:.1f} ms, rms {model.rms:.2f} rad/s, "
          f"v_ref {model.v_ref:.3f} V, b {model.b.round(1)}, c {model.c.round(1)}", flush=True)
    t0 = time.time()
    with_speeds = diagnose_per_flight(mixed, nominal, params)
    t1 = time.time()
    ref_cmd = [synthesise_speeds(without_speeds(g), model) for g in nominal]
    mix_cmd = [synthesise_speeds(without_speeds(g), model) for g in mixed]
    commands_only = diagnose_per_flight(mix_cmd, ref_cmd, params)
    t2 = time.time()
    # variant: reference flights keep their measured speeds, only the mixed ones lose them
    mixed_ref = diagnose_per_flight(mix_cmd, nominal, params)
    agree_ref = sum(a["verdict"] == b["verdict"] for a, b in
                    zip(with_speeds["flights"], mixed_ref["flights"]))
    refused = [f for f in mixed_ref["flights"] if f["verdict"] == "refused"]
    print(f"variant (reference with measured speeds): agreement {agree_ref}/{len(mixed)}"
          + (f"; {len(refused)} refused ({refused[0]['reason']})" if refused else ""))
    pairs = [(Path(a["file"]).name, a["verdict"], b["verdict"])
             for a, b in zip(with_speeds["flights"], commands_only["flights"])]
    agree = sum(a == b for _, a, b in pairs)
    for name, a, b in pairs:
        print(f"{name:24s} {a:22s} {b:22s} {'' if a == b else '<- differs'}")
    print(f"agreement {agree}/{len(pairs)} = {agree / len(pairs):.2f}; "
          f"{t1 - t0:.0f} s with speeds, {t2 - t1:.0f} s commands only")
    if args.json:
        Path(args.json).write_text(json.dumps(
            {"pairs": pairs, "agree_measured_reference": agree_ref,
             "flights_with": with_speeds["flights"], "flights_cmd": commands_only["flights"],
             "agreement": agree / len(pairs), "tau_s": model.tau, "rms_rad_s": model.rms},
            indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
