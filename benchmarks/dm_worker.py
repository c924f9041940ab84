"""drone-models flights in a fresh interpreter (the part of :mod:`.dm_source` that imports
drone-models).

``import drone_models`` needs SciPy's array-API mode (``SCIPY_ARRAY_API=1``), which must be
set before SciPy is first imported and must not be switched on in quadsim's process; so the
flights are flown here, in a child process (:func:`benchmarks.dm_source.dm_flights` starts
``python .../dm_worker.py JOB.npz OUT.npz``); this module imports nothing of quadsim.

What is drone-models' own (``drone_models.first_principles.dynamics``, tested with 0.1.0, the
``cf21B_500`` parameters of its ``data/params.toml``): the state derivative of the
quaternion rigid body with its thrust and torque curves (quadratic polynomials in RPM with a
linear term), its rotor dynamics (``rotor_dyn_coef``: different spin-up and spin-down
rates), its linear body-frame drag (``drag_matrix``), its propeller gyroscopic and
reaction torques, and its disturbance inputs ``dist_f`` / ``dist_t`` (world frame, at the
CoM). drone-models has no integrator and no controller; both are this module's:

* **integrator**: classic fixed-step RK4 at ``physics_hz`` (500 Hz) on the 17-state vector
  (position, xyzw quaternion, velocity, body rate, four rotor speeds in RPM), the motor
  command held over each step; every derivative is drone-models' own except the
  quaternion's (:func:`quat_dot`, from drone-models' body rate): drone-models 0.1.0's
  numeric ``quat_dot`` applies the scalar-first formula to its xyzw quaternion (at level, a
  body roll rate gives a yaw ``quat_dot``), and its docstring warns not to integrate
  ``quat_dot``, only the body rate; the quaternion is renormalised after each step;
* **controller** (:func:`control`): a cascade in the shape of the Crazyflie firmware's PID
  controller (``controller_pid.c``): position P + velocity PID with the path's velocity and
  acceleration fed forward at ``position_hz`` (100 Hz) -> collective thrust and roll/pitch
  angle setpoints; attitude P at ``attitude_hz`` (250 Hz) -> body-rate setpoints (yaw rate
  fed forward); rate PI + D on the measured rate at ``physics_hz`` (500 Hz) -> body torques;
  the firmware-style power distribution (thrust, roll, pitch and yaw torque -> four rotor
  thrusts through the nominal geometry and ``thrust2torque``), each clipped to
  [``thrust_min``, ``thrust_max``] and inverted through the nominal thrust curve to an RPM
  command. The controller knows only the nominal ``cf21B_500`` values, whatever the case.

Case changes, each through drone-models' own parameters or disturbance inputs: ``mass``
(F,), ``J`` (F, 3, 3) (a payload's full inertia), per-rotor factors ``rotor_scale`` (F, 4)
on ``rpm2thrust`` and ``rpm2torque``, ``motor_slow`` (F,) dividing ``rotor_dyn_coef`` (time
constants x factor), ``drag_scale`` (F,) on ``drag_matrix``; through ``dist_f`` /
``dist_t``: a wind ``wind`` (F, 3) world m/s as the drag matrix's force at the air speed,
``-R D R^T w`` (the model's drag acts on the ground speed), a CoM ``com`` (F, 3) body m off
the rotors' centre as the thrust's moment ``-c x (0, 0, T)`` (the model places the rotors
about the CoM), a rate damping ``rate_damping`` (F, 3) N m s/rad as ``-k w`` (body), a
periodic body torque ``torque`` (F, 3) N m at ``torque_hz`` (F,) and a periodic body-z force
``force`` (F,) N at ``force_hz`` (F,).

Job (``JOB.npz``), F flights of T physics steps: ``pos_sp``, ``vel_sp``, ``acc_sp`` (F, T, 3)
world m, m/s, m/s^2; ``yaw_sp``, ``yaw_rate_sp`` (F, T) rad, rad/s; the changes above;
``start`` (F, 3) position m and ``start_vel`` (F, 3) m/s; ``start_yaw`` (F,) rad;
``rotor0`` (F,) RPM; ``physics_hz``, ``position_hz``, ``attitude_hz``; ``drone`` (name).

Output (``OUT.npz``), per physics step k = 0..T-1 (state at t_k; the command and
derivatives that act from t_k): ``pos`` ``vel`` (CoM, world) ``quat`` (xyzw body -> world)
``ang_vel`` (body) ``rotor`` (RPM) ``cmd`` (RPM) ``acc`` (world, the state derivative)
``ang_acc`` (body). A flight that leaves control (non-finite, tilted past 60 deg, below
0.05 m) stops the job: exit 3 with one line naming it.
"""

from __future__ import annotations

import os
import sys

os.environ["SCIPY_ARRAY_API"] = "1"

OUTPUTS = ("pos", "vel", "quat", "ang_vel", "rotor", "cmd", "acc", "ang_acc")
#: controller gains (SI, per second: each loop's output per unit error; module doc): rate PI
#: 40 /s, 80 /s^2 and D 1.5 (angular acceleration per unit rate error, its integral, and per
#: unit angular acceleration), attitude 5 /s, velocity 2.5 /s (+ 1 /s^2 integral), position
#: 1.5 /s in the plane; z 2 /s, 5 /s, 2 /s^2; yaw 4 /s, rate 8 /s, 2 /s^2; tilt at most 0.5
#: rad. Chosen (before any case was flown) for phase margins of 70 deg (rate) and 70 deg
#: (attitude) with drone-models' 57 ms rotor time constant and still 47 / 69 deg at 2.5 x it
#: (the slowest motor case), a 3 ms loop delay included
GAINS = {"pos_xy": 1.5, "vel_xy": 2.5, "vel_xy_i": 1.0, "pos_z": 2.0, "vel_z": 5.0,
         "vel_z_i": 2.0, "att": 5.0, "att_yaw": 4.0, "rate": 40.0, "rate_i": 80.0,
         "rate_d": 1.5, "rate_yaw": 8.0, "rate_yaw_i": 2.0, "tilt_max": 0.5}
#: the rate integrals' limit (rad): with the rate I gain it bounds the angular acceleration
#: the integral may command, 80 x 30 = 2400 rad/s^2 (beyond the rotors' authority: no
#: limit in practice; the rotor thrust clip bounds the torque)
RATE_I_MAX = 30.0


def _rot(quat):
    """(F, 3, 3) body -> world rotation matrices of (F, 4) xyzw quaternions."""
    import numpy as np

    x, y, z, w = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w),
                               2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z),
                               2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w),
                               1 - 2 * (x * x + y * y)], -1)], 1)


def quat_dot(quat, w):
    """(F, 4) derivative of (F, 4) xyzw body -> world quaternions at body rates ``w`` (F, 3)
    rad/s: q' = q (x) (0, w) / 2, i.e. vector part (s w + v x w) / 2, scalar part -v.w / 2."""
    import numpy as np

    v, s = quat[:, 0:3], quat[:, 3:4]
    return 0.5 * np.concatenate([s * w + np.cross(v, w), -np.sum(v * w, axis=1,
                                                                   keepdims=True)], axis=1)


def _euler(quat):
    """(F,) roll, pitch, yaw (ZYX) of (F, 4) xyzw quaternions."""
    import numpy as np

    x, y, z, w = quat[:, 0], quat[:, 1], quat[:, 2], quat[:, 3]
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def rk4_step(deriv, x, cmd, t: float, dt: float, k1=None):
    """One classic RK4 step of ``deriv(x, cmd, t)`` (F, 17) over ``dt`` s with ``cmd`` held
    (``k1``: the derivative at (x, t) when already evaluated); the quaternion (columns 3-6)
    renormalised."""
    import numpy as np

    k1 = deriv(x, cmd, t) if k1 is None else k1
    k2 = deriv(x + 0.5 * dt * k1, cmd, t + 0.5 * dt)
    k3 = deriv(x + 0.5 * dt * k2, cmd, t + 0.5 * dt)
    k4 = deriv(x + dt * k3, cmd, t + dt)
    x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
    x[:, 3:7] /= np.linalg.norm(x[:, 3:7], axis=1, keepdims=True)
    return x


class Controller:
    """The firmware-shaped PID cascade of the module doc for F flights, nominal values ``p``
    (drone-models' parameter dict) and loop periods (s)."""

    def __init__(self, p: dict, flights: int, dt: float, position_every: int,
                 attitude_every: int):
        import numpy as np

        self.p, self.dt = p, dt
        self.position_every, self.attitude_every = position_every, attitude_every
        self.mass = float(p["mass"])
        self.J = np.asarray(p["J"], dtype=float)
        mix, arm = np.asarray(p["mixing_matrix"], dtype=float), float(p["L"])
        alloc = np.vstack([np.ones(4), arm * mix[0], arm * mix[1],
                           float(p["thrust2torque"]) * mix[2]])
        self.unalloc = np.linalg.inv(alloc)
        self.curve = np.asarray(p["rpm2thrust"], dtype=float)
        self.limits = float(p["thrust_min"]), float(p["thrust_max"])
        self.g = -float(np.asarray(p["gravity_vec"])[2])
        self.i_vel = np.zeros((flights, 3))
        self.i_rate = np.zeros((flights, 3))
        self.thrust = np.full(flights, self.mass * self.g)
        self.tilt = np.zeros((flights, 2))
        self.rate_sp = np.zeros((flights, 3))
        self.last_rate = None
        self.cmd = None

    def rpm(self, thrust):
        """RPM of a rotor thrust (N) on the nominal curve a + b rpm + c rpm^2."""
        import numpy as np

        a, b, c = self.curve
        return (-b + np.sqrt(b * b - 4 * c * (a - thrust))) / (2 * c)

    def step(self, k: int, x, sp: dict):
        """RPM commands (F, 4) at physics step ``k`` of states ``x`` (F, 17), setpoints
        ``sp`` of this step (pos, vel, acc (F, 3); yaw, yaw_rate (F,))."""
        import numpy as np

        gk = GAINS
        pos, quat, vel, w = x[:, 0:3], x[:, 3:7], x[:, 7:10], x[:, 10:13]
        roll, pitch, yaw = _euler(quat)
        if k % self.position_every == 0:
            dt = self.dt * self.position_every
            kp = np.array([gk["pos_xy"], gk["pos_xy"], gk["pos_z"]])
            kv = np.array([gk["vel_xy"], gk["vel_xy"], gk["vel_z"]])
            ki = np.array([gk["vel_xy_i"], gk["vel_xy_i"], gk["vel_z_i"]])
            err = sp["vel"] + kp * (sp["pos"] - pos) - vel
            self.i_vel = np.clip(self.i_vel + err * dt, -2.0, 2.0)
            acc = sp["acc"] + kv * err + ki * self.i_vel
            up = np.maximum(acc[:, 2] + self.g, 0.3 * self.g)
            c, s = np.cos(yaw), np.sin(yaw)
            ax, ay = c * acc[:, 0] + s * acc[:, 1], -s * acc[:, 0] + c * acc[:, 1]
            lim = gk["tilt_max"]
            self.tilt = np.stack([np.clip(np.arctan2(-ay, up), -lim, lim),
                                  np.clip(np.arctan2(ax, up), -lim, lim)], -1)
            self.thrust = self.mass * up / np.maximum(np.cos(roll) * np.cos(pitch), 0.5)
        if k % self.attitude_every == 0:
            yaw_err = (sp["yaw"] - yaw + np.pi) % (2 * np.pi) - np.pi
            self.rate_sp = np.stack([gk["att"] * (self.tilt[:, 0] - roll),
                                     gk["att"] * (self.tilt[:, 1] - pitch),
                                     gk["att_yaw"] * yaw_err + sp["yaw_rate"]], -1)
        err = self.rate_sp - w
        self.i_rate = np.clip(self.i_rate + err * self.dt, -RATE_I_MAX, RATE_I_MAX)
        rate_acc = (w - (w if self.last_rate is None else self.last_rate)) / self.dt
        self.last_rate = w.copy()
        kr = np.array([gk["rate"], gk["rate"], gk["rate_yaw"]])
        kri = np.array([gk["rate_i"], gk["rate_i"], gk["rate_yaw_i"]])
        krd = np.array([gk["rate_d"], gk["rate_d"], 0.0])
        alpha = kr * err + kri * self.i_rate - krd * rate_acc
        torque = alpha @ self.J.T
        wrench = np.concatenate([self.thrust[:, None], torque], axis=1)
        rotor_thrust = np.clip(wrench @ self.unalloc.T, *self.limits)
        return self.rpm(rotor_thrust)


def fly(job: dict) -> dict:
    """Every flight of ``job`` at once (module doc); the outputs (F, T, ...)."""
    import numpy as np
    from drone_models.core import load_params
    from drone_models.first_principles import dynamics

    drone = str(job["drone"])
    p = load_params("first_principles", drone)
    physics_hz = int(job["physics_hz"])
    dt = 1.0 / physics_hz
    flights, steps = job["pos_sp"].shape[:2]
    one = np.ones((flights, 1))
    scale = np.asarray(job["rotor_scale"], dtype=float)                       # (F, 4)
    drag = np.asarray(p["drag_matrix"], dtype=float)[None] * job["drag_scale"][:, None, None]
    J = np.asarray(job["J"], dtype=float)
    kw = {"mass": np.asarray(job["mass"], dtype=float)[:, None], "L": p["L"],
          "prop_inertia": p["prop_inertia"], "gravity_vec": p["gravity_vec"], "J": J,
          "J_inv": np.linalg.inv(J),
          "rpm2thrust": np.asarray(p["rpm2thrust"], dtype=float)[:, None, None] * scale[None],
          "rpm2torque": np.asarray(p["rpm2torque"], dtype=float)[:, None, None] * scale[None],
          "mixing_matrix": p["mixing_matrix"], "drag_matrix": drag,
          "rotor_dyn_coef": np.asarray(p["rotor_dyn_coef"], dtype=float)[:, None, None]
          / job["motor_slow"][None, :, None] * np.ones((1, 1, 4))}
    com, wind = np.asarray(job["com"], dtype=float), np.asarray(job["wind"], dtype=float)
    damping = np.asarray(job["rate_damping"], dtype=float)
    push, push_hz = np.asarray(job["force"], dtype=float), np.asarray(job["force_hz"], float)
    twist, twist_hz = np.asarray(job["torque"], dtype=float), np.asarray(job["torque_hz"],
                                                                         float)
    curve = kw["rpm2thrust"]

    def deriv(x, cmd, t):
        pos, quat, vel, w, rotor = x[:, 0:3], x[:, 3:7], x[:, 7:10], x[:, 10:13], x[:, 13:17]
        rot = _rot(quat / np.linalg.norm(quat, axis=1, keepdims=True))
        thrust = np.sum(curve[0] + curve[1] * rotor + curve[2] * rotor ** 2, axis=1)
        air = np.einsum("fji,fj->fi", rot, wind)                       # R^T w
        dist_f = -np.einsum("fij,fj->fi", rot, np.einsum("fij,fj->fi", drag, air))
        dist_f = dist_f + np.einsum("fij,fj->fi", rot, np.stack(
            [0 * push, 0 * push, push * np.sin(2 * np.pi * push_hz * t)], -1))
        body_t = (np.stack([-com[:, 1] * thrust, com[:, 0] * thrust, 0 * thrust], -1)
                  - damping * w + twist * np.sin(2 * np.pi * twist_hz * t)[:, None])
        dist_t = np.einsum("fij,fj->fi", rot, body_t)
        d = list(dynamics(pos, quat, vel, w, cmd, rotor, dist_f, dist_t, **kw))
        d[1] = quat_dot(quat, w)                     # not drone-models' own (module doc)
        return np.concatenate(d, axis=1)

    x = np.zeros((flights, 17))
    x[:, 0:3] = job["start"]
    yaw0 = np.asarray(job["start_yaw"], dtype=float)
    x[:, 3:7] = np.stack([0 * yaw0, 0 * yaw0, np.sin(yaw0 / 2), np.cos(yaw0 / 2)], -1)
    x[:, 7:10] = job["start_vel"]
    x[:, 13:17] = np.asarray(job["rotor0"], dtype=float)[:, None] * one
    ctrl = Controller(p, flights, dt, physics_hz // int(job["position_hz"]),
                      physics_hz // int(job["attitude_hz"]))
    out = {k: np.zeros((flights, steps, 4 if k in ("quat", "rotor", "cmd") else 3))
           for k in OUTPUTS}
    for k in range(steps):
        t = k * dt
        sp = {"pos": job["pos_sp"][:, k], "vel": job["vel_sp"][:, k],
              "acc": job["acc_sp"][:, k], "yaw": job["yaw_sp"][:, k],
              "yaw_rate": job["yaw_rate_sp"][:, k]}
        cmd = ctrl.step(k, x, sp)
        k1 = deriv(x, cmd, t)
        for name, value in (("pos", x[:, 0:3]), ("vel", x[:, 7:10]), ("quat", x[:, 3:7]),
                            ("ang_vel", x[:, 10:13]), ("rotor", x[:, 13:17]), ("cmd", cmd),
                            ("acc", k1[:, 7:10]), ("ang_acc", k1[:, 10:13])):
            out[name][:, k] = value
        x = rk4_step(deriv, x, cmd, t, dt, k1)
        tilt = 1 - 2 * (x[:, 3] ** 2 + x[:, 4] ** 2)                     # R[2, 2]
        bad = ~np.all(np.isfinite(x), axis=1) | (tilt < 0.5) | (x[:, 2] < 0.05)
        if np.any(bad):
            raise SystemExit(f"drone-models flight {int(np.argmax(bad))} lost control at "
                             f"t = {t:.3f} s")
    return out


def run(job_path: str, out_path: str) -> None:
    import warnings

    import numpy as np

    warnings.simplefilter("ignore")
    with np.load(job_path) as data:
        job = {k: np.array(data[k]) for k in data.files}
    try:
        out = fly(job)
    except SystemExit as exc:
        print(str(exc), file=sys.stderr)
        sys.exit(3)
    tmp = out_path + ".tmp.npz"
    np.savez(tmp, **out)
    os.replace(tmp, out_path)


if __name__ == "__main__":
    run(sys.argv[1], sys.argv[2])
