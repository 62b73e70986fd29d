"""N simulated rigs that are reset one by one and stepped together: the batch engine with episodes.

``VectorRig`` is what a vector environment steps (``twin.app.envs``): rig i is ``SimRig`` i (the MuJoCo twin,
full I/O chain or ideal converters) bit for bit, whenever it was last reset, and all of them step as rows
of one ``mujoco.batch.Batch``.

Runs reset together share their time base and their sensor, DAQ and timing parameters; such a cohort is a
``twin.rigs.batch.BatchRig`` (the batch engine's runs in step, its numpy stages over its rows) stepping rows
``ids`` of the shared batch. A reset makes a new cohort of the rigs reset (their start blocks, −1 and 0, are
read at once: the held rig, the free run, release), and leaves them out of their old one; a cohort whose
rigs were all reset is dropped. Every block after a rig's block 0 is one control period of physics, so a
step is one rollout of every rig still going (each row on its own model: its episode's parameters), then
each cohort's sensors. The clocks differ from cohort to cohort, which is why the numpy stages do not span
them: a block's filter weights depend on its clock's rounding, and a rig alone has its own clock.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from twin.interface import RigError
from twin.parameters import Parameters
from twin.plant import FULL_STATE, Plant
from twin.plant_batch import MujocoBatchPhysics
from twin.rigs.batch import BatchRig, BatchSamples, batch_key
from twin.rigs.sim import tick_schedule

__all__ = ["VectorBlocks", "VectorRig"]

PLANTS_KEPT = 256  # compiled models kept for reuse beyond those in use (domain randomization makes new ones)


@dataclass(frozen=True)
class VectorBlocks:
    """One block of each rig asked for (rows in the order asked), with what the simulation knows of it."""

    time_s: np.ndarray  # (n,) the block's time (each rig's own clock)
    ball_v: np.ndarray  # (n,) ADC volts
    angle_v: np.ndarray  # (n,) ADC volts
    state: np.ndarray  # (n, 4) true (x, θ, ẋ, θ̇) after the block: simulation only
    motor_v: np.ndarray  # (n,) volts across the motor at the block's end
    peak_theta_rad: np.ndarray  # (n,) largest |θ| over the block's steps on the track
    ball_lost: np.ndarray  # (n,) bool
    true_time_s: np.ndarray  # (n,) the simulation's clock after the block (negative while held)
    lost_time_s: np.ndarray  # (n,) when the ball left the track (NaN while it has not)


class VectorRig:
    """``n`` rigs on one batch; ``reset`` some, ``step`` every rig not being reset (see the module)."""

    def __init__(
        self, n: int, params: Parameters, *, ideal_sensors: bool = False, nthread: int | None = None
    ):
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n = {n!r}: a vector of at least one rig")
        self.n = n
        self.ideal_sensors = bool(ideal_sensors)
        self.schedule_key = _steps_key(params)
        self._plants: dict[Parameters, Plant] = {}
        first = self._plant(params)
        threads = (os.cpu_count() or 1) if nthread is None else int(nthread)
        self.batch = mjbatch.Batch(first.model, n, nthread=threads)
        self.models: list[mujoco.MjModel] = [first.model] * n
        self._nfull = mujoco.mj_stateSize(first.model, FULL_STATE)
        self.cohort_of: list[BatchRig | None] = [None] * n  # each rig's cohort
        self.row_in: np.ndarray = np.zeros(n, dtype=np.int64)  # its index within the cohort
        self.cohorts: list[BatchRig] = []
        self.physics_of: dict[int, MujocoBatchPhysics] = {}  # each cohort's rows of the batch (by id)
        self.rig_params: list[Parameters | None] = [None] * n  # each rig's episode parameters

    def _plant(self, params: Parameters) -> Plant:
        plant = self._plants.get(params)
        if plant is None:
            if len(self._plants) > PLANTS_KEPT + self.n:  # keep the models in use, drop the oldest others
                in_use = set(self.rig_params)
                for q in list(self._plants):
                    if q not in in_use:
                        del self._plants[q]
                        if len(self._plants) <= PLANTS_KEPT:
                            break
            plant = self._plants[params] = Plant(params)
        return plant

    def reset(
        self,
        rigs: Sequence[int] | np.ndarray,
        params: Sequence[Parameters],
        x0_m: np.ndarray,
        theta0_rad: np.ndarray,
        seeds: np.ndarray,
    ) -> tuple[VectorBlocks, VectorBlocks]:
        """Hold rigs ``rigs`` at their initial states with their episode's parameters and noise seeds, and
        read their start block (k = −1, what ``Controller.start`` reads) and block 0: ``SimRig(params[j],
        seed=seeds[j]).reset(x0_m[j], theta0_rad[j])`` then two ``read()``, for each j."""
        rows = np.asarray(rigs, dtype=np.int64).reshape(-1)
        if len(set(rows.tolist())) != len(rows) or (
            len(rows) and not (0 <= rows.min() and rows.max() < self.n)
        ):
            raise ValueError(f"rigs {rows.tolist()}: distinct indices 0…{self.n - 1}")
        for q in params:
            if _steps_key(q) != self.schedule_key:
                raise RigError(
                    "a vector's rigs step together: every episode's physics.timestep_s and daq.period_s must be "
                    f"the first's ({self.schedule_key[0]!r} s, {self.schedule_key[1]!r} s)"
                )
        for r in rows.tolist():  # out of their old cohorts
            self._leave(r)
        groups: dict[tuple, list[int]] = {}
        for j, q in enumerate(params):
            groups.setdefault(batch_key(q), []).append(j)
        for j, r in enumerate(rows.tolist()):
            self.rig_params[r] = params[j]  # in use from now: kept in the cache
            self.models[r] = self._plant(params[j]).model
        self.batch.set_models(self.models)
        starts, firsts = _Blocks(len(rows)), _Blocks(len(rows))
        for listed in groups.values():
            members = sorted(listed, key=lambda j: int(rows[j]))  # a rollout takes its rows in order
            ids = rows[members]
            qs = [params[j] for j in members]
            x0, theta0 = np.asarray(x0_m, dtype=float)[members], np.asarray(theta0_rad, dtype=float)[members]
            physics = MujocoBatchPhysics(
                qs, x0, theta0, self.batch.nthread, batch=self.batch, ids=ids, plant_cache=self._plants
            )
            cohort = BatchRig(
                qs, x0, theta0, np.asarray(seeds)[members], physics=physics, ideal_sensors=self.ideal_sensors,
                record=False,
            )  # fmt: skip
            self.physics_of[id(cohort)] = physics
            self.cohorts.append(cohort)
            for k, r in enumerate(ids.tolist()):
                self.cohort_of[r] = cohort
                self.row_in[r] = k
            at = np.asarray(members)
            starts.fill(at, cohort, cohort.read())
            firsts.fill(at, cohort, cohort.read())
        return starts.done(), firsts.done()

    def _leave(self, rig: int) -> None:
        cohort = self.cohort_of[rig]
        if cohort is None:
            return
        self.cohort_of[rig] = None
        k = int(self.row_in[rig])
        cohort.live = cohort.live[cohort.live != k]
        if not len(cohort.live):
            self.cohorts.remove(cohort)
            del self.physics_of[id(cohort)]

    def step(self, rigs: Sequence[int] | np.ndarray, command_v: np.ndarray) -> VectorBlocks:
        """Write each rig's DAC command (volts) and read its next block: ``SimRig.write`` then ``read()``
        for every rig in ``rigs`` (each reset before; in any order), all in one rollout."""
        rows = np.asarray(rigs, dtype=np.int64).reshape(-1)
        cmd = np.asarray(command_v, dtype=float).reshape(-1)
        if len(cmd) != len(rows):
            raise ValueError(f"{len(cmd)} commands for {len(rows)} rigs")
        result = _Blocks(len(rows))
        if not len(rows):
            return result.done()
        which: dict[int, list[int]] = {}  # cohort (by id) → positions in rows
        cohorts: dict[int, BatchRig] = {}
        for j, r in enumerate(rows.tolist()):
            cohort = self.cohort_of[r]
            if cohort is None:
                raise RigError(f"rig {r} has not been reset")
            which.setdefault(id(cohort), []).append(j)
            cohorts[id(cohort)] = cohort
        plans = []
        for key, listed in which.items():
            cohort, positions = cohorts[key], np.asarray(listed)
            members = self.row_in[rows[positions]]
            if not np.array_equal(np.sort(members), cohort.live):
                raise RigError(
                    "a cohort's rigs step together: step every rig reset with it that is still going"
                )
            order = np.argsort(members)  # the cohort's live order
            commands = np.empty(len(positions))
            commands[:] = cmd[positions[order]]
            cohort.write(commands)
            if not cohort.schedule.next_is_observed():
                raise RigError(
                    "a rig's next block is not one period of physics (read its start blocks first)"
                )
            t0, volts = cohort.begin_observed()
            plans.append((cohort, positions[order], t0, volts))
        volts_all = np.concatenate([v for _, _, _, v in plans], axis=0)
        ids_all = np.concatenate([self.physics_of[id(c)].ids[c.live] for c, _, _, _ in plans])
        steps = volts_all.shape[1]
        if len(ids_all) < 2 or bool((np.diff(ids_all) > 0).all()):
            out_all = self.batch.rollout(
                steps, control=volts_all[:, :, None], record=(FULL_STATE,), ids=ids_all
            )[FULL_STATE]
        else:  # a rollout takes its rows in order
            order = np.argsort(ids_all)
            out_all = np.empty((len(ids_all), steps, self._nfull))
            out_all[order] = self.batch.rollout(
                steps, control=volts_all[order, :, None], record=(FULL_STATE,), ids=ids_all[order]
            )[FULL_STATE]
        at = 0
        for cohort, positions, t0, volts in plans:
            m = len(volts)
            block = self.physics_of[id(cohort)].advanced(cohort.live, t0, out_all[at : at + m])
            result.fill(positions, cohort, cohort.end_observed(t0, block))
            at += m
        return result.done()


def _steps_key(p: Parameters) -> tuple[float, float]:
    tick_schedule(p)  # a period and latency of whole physics steps (RigError otherwise)
    return (p.physics.timestep_s, p.period_s)


class _Blocks:
    """``VectorBlocks`` being filled cohort by cohort."""

    def __init__(self, n: int) -> None:
        self.time_s, self.ball_v, self.angle_v = np.empty(n), np.empty(n), np.empty(n)
        self.state, self.motor_v, self.peak = np.empty((n, 4)), np.empty(n), np.empty(n)
        self.lost = np.zeros(n, dtype=bool)
        self.true_time_s, self.lost_time_s = np.empty(n), np.full(n, np.nan)

    def fill(self, at: np.ndarray, cohort: BatchRig, samples: BatchSamples) -> None:
        """Rows ``at``: the cohort's live rigs' block just read, with their true state (``BatchRig``'s, as the
        batch engine logs it)."""
        live = cohort.live
        self.time_s[at] = samples.time_s
        self.ball_v[at] = samples.ball_v
        self.angle_v[at] = samples.angle_v
        self.state[at] = cohort.true_state()
        self.motor_v[at] = cohort.applied_v[live]
        self.peak[at] = cohort.block_peaks()
        self.lost[at] = cohort.lost[live]
        self.true_time_s[at] = cohort.time_s
        if cohort.lost[live].any():
            self.lost_time_s[at] = [np.nan if t is None else t for t in (cohort.lost_time_s[k] for k in live)]

    def done(self) -> VectorBlocks:
        return VectorBlocks(
            self.time_s,
            self.ball_v,
            self.angle_v,
            self.state,
            self.motor_v,
            self.peak,
            self.lost,
            self.true_time_s,
            self.lost_time_s,
        )
