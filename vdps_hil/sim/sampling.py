"""What the sensor models read and when: the truth of every integration step
(:class:`StepRecorder` -> :class:`Block`), each sensor's sampling instants (:class:`Sampler`) and
its seeded random streams (:func:`rng_for`). The sensor models are :mod:`vdps_hil.sim.sensors`.

Sampling
--------
A :class:`StepRecorder` hooked into the simulator keeps, at every integration step n (time
t_n = n dt), the kinematics and inputs a sensor needs. A sensor of rate f samples at
t_k = n_k dt with n_k = round(k / (f dt)) (exact for the profiles' rates, which divide 1 kHz).

Random streams
--------------
Every sensor has its own generators, ``numpy.random.default_rng(SeedSequence(seed,
spawn_key=(crc32(name),)))`` for names such as ``imu.noise``, ``imu.calibration``,
``gnss.position``: one seed reproduces the whole drive, and adding a sensor or a fault never
changes another sensor's draws.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from vdps_hil.units import NS_PER_S

__all__ = ["Block", "Sampler", "StepRecorder", "rng_for"]


def rng_for(seed: int, name: str) -> np.random.Generator:
    """The generator of stream ``name`` of a drive seeded with ``seed`` (module docstring)."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(zlib.crc32(name.encode()),)))


_COLS = ("n", "f_x", "f_y", "f_z", "w_x", "w_y", "w_z", "wd_x", "wd_y", "wd_z",
         "pos_e", "pos_n", "pos_u", "roll", "pitch", "yaw", "u", "v", "w",
         "spin_1", "spin_2", "spin_3", "spin_4", "susp_1", "susp_2", "susp_3", "susp_4",
         "steer", "drive_1", "drive_2", "drive_3", "drive_4", "brake_1", "brake_2", "brake_3", "brake_4")
_C = {name: i for i, name in enumerate(_COLS)}


@dataclass
class Block:
    """Per-step truth over consecutive steps: ``n`` step indices, ``t_ns`` times, ``a`` the
    (N, 36) array of columns (see the accessors; SI, body axes, ENU)."""

    n: np.ndarray
    t_ns: np.ndarray
    a: np.ndarray

    def __len__(self) -> int:
        return len(self.n)

    def col(self, name: str) -> np.ndarray:
        return self.a[:, _C[name]]

    def cols(self, first: str, k: int) -> np.ndarray:
        i = _C[first]
        return self.a[:, i:i + k]

    specific_force = property(lambda s: s.cols("f_x", 3))
    rate = property(lambda s: s.cols("w_x", 3))
    angular_accel = property(lambda s: s.cols("wd_x", 3))
    pos = property(lambda s: s.cols("pos_e", 3))
    euler = property(lambda s: s.cols("roll", 3))
    vel_b = property(lambda s: s.cols("u", 3))
    wheel_spin = property(lambda s: s.cols("spin_1", 4))
    susp = property(lambda s: s.cols("susp_1", 4))
    steer = property(lambda s: s.col("steer"))
    drive_torque = property(lambda s: s.cols("drive_1", 4))
    brake_torque = property(lambda s: s.cols("brake_1", 4))

    def take(self, rows: np.ndarray) -> "Block":
        return Block(self.n[rows], self.t_ns[rows], self.a[rows])

    _GROUPS = {"specific_force": ("f_x", 3), "rate": ("w_x", 3), "angular_accel": ("wd_x", 3),
               "pos": ("pos_e", 3), "euler": ("roll", 3), "vel_b": ("u", 3),
               "wheel_spin": ("spin_1", 4), "susp": ("susp_1", 4), "steer": ("steer", 1),
               "drive_torque": ("drive_1", 4), "brake_torque": ("brake_1", 4)}

    @classmethod
    def build(cls, n: np.ndarray, dt_ns: int, **groups: np.ndarray) -> "Block":
        """A block from arrays named like the accessors (missing groups are zero); ``n`` are
        consecutive step indices. For tests and for driving the sensors without the simulator."""
        n = np.asarray(n, dtype=np.int64)
        a = np.zeros((len(n), len(_COLS)))
        a[:, 0] = n
        for name, value in groups.items():
            first, k = cls._GROUPS[name]
            a[:, _C[first]:_C[first] + k] = np.asarray(value, dtype=float).reshape(len(n), k)
        return cls(n, n * np.int64(dt_ns), a)


class StepRecorder:
    """Records the truth a sensor needs at every step of a Simulator (and at the step where it
    is attached): the compiled steps write the rows themselves (``sim.attach_recorder``), else a
    step hook computes them (``sim.kinematics()``). ``take()`` returns the rows recorded since
    the last call."""

    def __init__(self, sim):
        self.sim = sim
        lay = sim.model.layout
        self._susp = lay.slices.get("susp_defl")
        self._buf = np.empty((1024, len(_COLS)))
        self._pos = 0
        attach = getattr(sim, "attach_recorder", None)
        if attach is not None and attach(self):
            return
        self._hook(sim)
        sim.add_step_hook(self._hook)

    def reserve(self, m: int) -> np.ndarray:
        """Room for the next ``m`` rows (a view the simulator fills; ``commit`` keeps them)."""
        if self._pos + m > len(self._buf):
            grown = np.empty((max(2 * len(self._buf), self._pos + m), len(_COLS)))
            grown[:self._pos] = self._buf[:self._pos]
            self._buf = grown
        return self._buf[self._pos:self._pos + m]

    def commit(self, m: int) -> None:
        self._pos += m

    def _hook(self, sim) -> None:
        k = sim.kinematics()
        u = sim.current_inputs()
        x = sim.x
        r = [float(sim.n), *k.specific_force_mps2, *k.angular_rate_radps, *k.angular_accel_radps2, *x[0:9],
             *x[12:16]]
        if self._susp is not None:
            r.extend(x[self._susp])
        else:  # reduced model: deflections follow from the pose (slow path, rarely used)
            _, d = sim.model.evaluate(x, u, sim.env)
            r.extend(d[f"susp_deflection_m_{i}"] for i in range(1, 5))
        r.append(u.steer_wheel_angle_rad)
        r.extend(u.wheel_torque_nm)
        r.extend(u.brake_torque_nm)
        self.reserve(1)[0] = r
        self.commit(1)

    def take(self) -> Block:
        a = self._buf[:self._pos].copy()
        self._pos = 0
        n = a[:, 0].astype(np.int64)
        return Block(n, n * np.int64(self.sim.dt_ns), a)


class Sampler:
    """Which steps a sensor of rate ``rate_hz`` samples: n_k = round(k T / dt)."""

    def __init__(self, rate_hz: float, dt_ns: int):
        if rate_hz <= 0:
            raise ValueError("rate must be positive")
        self.period_ns = int(round(NS_PER_S / rate_hz))
        self.dt_ns = int(dt_ns)
        self.k = 0

    def pick(self, block: Block) -> tuple[np.ndarray, np.ndarray]:
        """(rows of the block, sample numbers k) of the samples falling in this block."""
        if len(block) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        n0, n1 = int(block.n[0]), int(block.n[-1])
        span = (n1 - n0 + 1) * self.dt_ns // self.period_ns + 2
        ks = np.arange(self.k, self.k + span, dtype=np.int64)
        nk = (2 * ks * self.period_ns + self.dt_ns) // (2 * self.dt_ns)
        sel = nk <= n1
        ks, nk = ks[sel], nk[sel]
        if len(ks) and nk[0] < n0:
            raise RuntimeError("sampler fell behind the recorded steps")
        if len(ks):
            self.k = int(ks[-1]) + 1
        return nk - n0, ks
