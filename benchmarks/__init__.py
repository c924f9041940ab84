"""The benchmark harness beside the package (repository only, not in the wheel; quadsim never
imports it; benchmarks/README.md): the blind and independent benchmarks of the gap diagnosis,
the nano-drone benchmark, and the generators the tests share (:mod:`.synthetic` flights,
:mod:`.corrupt` logs).

The self-generated blind benchmark (``benchmarks/gap_benchmark.py``) flies each hidden effect
through the same hooks the diagnosis fits, on inverse-dynamics logs with perfect sensor
timing. This package provides sources that break that circle:

* :mod:`.rotorpy_source` -- RotorPy (``pip install -e '.[independent]'``): its own SE(3)
  controller, RK45 integrator, motor model, aerodynamics, IMU and motion-capture models;
  effects injected as RotorPy parameters (mass, rotor positions about the CoM, inertia, one
  rotor's k_eta and k_m, tau_m, drag coefficients, wind profiles, flapping, translational
  lift), the log converted to quadsim's :class:`~quadsim.logs.flightlog.FlightLog` (xyzw -> wxyz);
* :mod:`.pipeline` -- quadsim's closed loop through a realistic sensor pipeline
  (finite-difference accelerometer from mocap, filtered and delayed rotor speeds, mocap
  latency, noise, bias, quantisation);
* :mod:`.crazyflow_source` -- Crazyflow (``pip install -e '.[crazyflow]'``): its own
  first-principles dynamics, RK4 integrator, Mellinger controller and Crazyflie 2.1
  Brushless, run in a child process (:mod:`.crazyflow_worker`); :mod:`.crazyflow_cases` --
  its 28 frozen single-flight cases, judged per flight against 8 nominal Crazyflow flights
  (``benchmarks/gap_benchmark.py --independent --source crazyflow --cache DIR``);
* :mod:`.pyflyt_source` -- PyFlyt 0.29.0 (``pip install -e '.[pyflyt]'`` then ``pip
  install --no-deps PyFlyt==0.29.0``): pybullet physics, its own QuadX (``cf2x``), motors,
  drag, rate damping and PID cascade, run in a child process (:mod:`.pyflyt_worker`);
  :mod:`.pyflyt_cases` -- its 28 frozen single-flight cases against 8 nominal PyFlyt
  flights (``--source pyflyt``);
* :mod:`.multirotor_source` -- multirotor 0.5.0 (its DC motors, odeint rigid body and
  ArduPilot-style PID; a 5.5 kg quadrotor); :mod:`.multirotor_cases` -- 28 frozen cases
  (``--source multirotor``);
* :mod:`.l2f_source` -- l2f 2.0.18 (``pip install -e '.[l2f]'``, a C++ build): RLtools'
  Learning to Fly simulator, single-precision RK4, first-order rotors, its identified 2.0 kg
  Holybro X500, flown by a PID cascade of this module's; :mod:`.l2f_cases` -- 30 frozen
  cases (``--source l2f``); :mod:`.l2f_fs_cases` -- 30 of l2f's fs vehicle (3.35 kg, a
  thrust curve with constant and linear terms; ``--source l2f-fs``); :mod:`.simlog` (the
  sensor model) and :mod:`.sim_cases` (fly, cache, check, judge) are shared by the
  simulator sources;
* :mod:`.draws` -- realistic random magnitudes per vehicle; :mod:`.outside` -- effects
  outside the library; :mod:`.cases` -- the case list and the judging in held-out and
  per-flight mode; :mod:`.observe` -- whether a flight's true difference from its
  references shows in it (per-flight observability, every per-flight source);
  :mod:`.score` -- reading a verdict and scoring it.

Run: ``python -m benchmarks.gap_benchmark --independent --jobs 2 --out indep.json``; results
and their reading: docs/gap.md, "Independent benchmark".
"""
