"""The MuJoCo twin over N runs (``twin.physics.BatchPhysics``): one ``mujoco.batch.Batch`` call per block for
every run still going, on C threads, one state row per run (solver warm start included), so that each run's
trajectory is the one ``twin.plant.Plant`` steps alone. The batch engine (``twin.rigs.batch.BatchRig``) runs
its sensor chains over these blocks; ``twin.rigs.backends`` registers it as the twin's batch.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from twin.parameters import Parameters
from twin.physics import BatchBlock, BatchClock
from twin.plant import (
    FULL_STATE,
    Plant,
    beyond_stops,
    failure_time_s,
    numerical_failure,
    stop_overshoot_bound_rad,
    warning_text,
)

__all__ = ["MujocoBatchPhysics"]

_INTEGRATION = mujoco.mjtState.mjSTATE_INTEGRATION


class MujocoBatchPhysics(BatchClock):
    """N runs of ``Plant`` as rows of one ``mujoco.batch.Batch`` (see the module)."""

    def __init__(
        self,
        params: Sequence[Parameters],
        x0: np.ndarray,
        theta0: np.ndarray,
        nthread: int,
        *,
        batch: mjbatch.Batch | None = None,
        ids: np.ndarray | None = None,
        plant_cache: dict[Parameters, Plant] | None = None,
    ) -> None:
        """Each run's physics reset to its start (the single run's reset and its checks). ``batch``/``ids``:
        step these runs as rows ``ids`` of a batch shared with other groups (whose models the owner sets),
        instead of a batch of their own. ``plant_cache``: plants already built, by parameters (a group built
        for each episode need not compile its models again)."""
        self.n = n = len(params)
        self.dt = params[0].physics.timestep_s
        # One Plant per distinct physics: its model for the batch, its geometry for the numpy stages.
        plants: dict[Parameters, Plant] = {}
        for q in params:
            if q not in plants:
                cached = None if plant_cache is None else plant_cache.get(q)
                plants[q] = cached if cached is not None else Plant(q)
        self.plants = [plants[q] for q in params]
        self.distinct = list(plants.values())
        # The numpy of the track's coordinates and the true state, once per track shape (Plant.frame_key)
        # rather than once per plant: each run's rows through one plant of its shape.
        shapes: dict[tuple, Plant] = {}
        for plant in self.distinct:
            shapes.setdefault(plant.frame_key, plant)
        self.shapes = list(shapes.values())
        shape_index = {key: k for k, key in enumerate(shapes)}
        self.shape_of = np.array([shape_index[plants[q].frame_key] for q in params])
        states = np.empty((n, mujoco.mj_stateSize(self.distinct[0].model, _INTEGRATION)))
        nfull = mujoco.mj_stateSize(self.distinct[0].model, FULL_STATE)
        self.last_row = np.empty((n, nfull))  # each run's state after its last step (MjData's, alone)
        for i, plant in enumerate(self.plants):
            plant.reset(float(x0[i]), float(theta0[i]))  # the single run's reset (and its checks)
            mujoco.mj_getState(plant.model, plant.data, states[i], _INTEGRATION)
            mujoco.mj_getState(plant.model, plant.data, self.last_row[i], FULL_STATE)
        if batch is None:
            self.batch = mjbatch.Batch(self.distinct[0].model, n, nthread=nthread)
            self.ids = np.arange(n)
            if len(self.distinct) > 1:
                self.batch.set_models([plant.model for plant in self.plants])
        else:
            assert ids is not None and len(ids) == n
            self.batch, self.ids = batch, np.asarray(ids)
            batch.warning[self.ids] = 0  # a row's counters are its run's (MjData's, reset with it)
        self.batch.state[self.ids] = states
        # Each run's furthest physical beam angle (Plant._check_numerics): past it, a numerical failure.
        self.theta_limit_rad = np.array([q.beam.stop_angle_rad + stop_overshoot_bound_rad(q) for q in params])
        plant0 = self.distinct[0]
        assert plant0._hinge_qpos is not None
        self.theta_col = 1 + plant0._hinge_qpos
        self.ball_col = 1 + plant0._ball_qpos
        super().__init__(n, float(self.last_row[0, 0]))
        self.lost_state = np.full((n, 4), math.nan)

    def advance(self, runs: np.ndarray, volts: np.ndarray) -> BatchBlock:
        """Plant.advance for runs ``runs``: one rollout of their rows."""
        t0 = self._time_s
        out = self.batch.rollout(
            volts.shape[1], control=volts[:, :, None], record=(FULL_STATE,), ids=self.ids[runs]
        )[FULL_STATE]
        return self.advanced(runs, t0, out)

    def advanced(self, runs: np.ndarray, t0: float, out: np.ndarray) -> BatchBlock:
        """``advance`` once runs ``runs`` have been rolled out from ``t0`` by the batch's owner (a vector
        rig's one rollout of several groups): ``out`` their recorded states."""
        live, m = runs, out.shape[1]
        self._check_numerics(runs, t0, out)
        last = out[:, -1]
        if not np.isfinite(last).all():
            i = int(live[np.flatnonzero(~np.isfinite(last).all(axis=1))[0]])
            raise numerical_failure(
                self.plants[i].params, f"run {i}: the MuJoCo state is not finite", float(last[0, 0])
            )
        if not (last[:, 0] == last[0, 0]).all():
            raise RuntimeError("the runs of a batch fell out of step")
        theta = np.concatenate(
            [self.last_row[live, self.theta_col][:, None], out[:, :, self.theta_col]], axis=1
        )
        c = self.ball_col
        xyz = np.concatenate([self.last_row[live, None, c : c + 3], out[:, :, c : c + 3]], axis=1)
        along = np.empty_like(theta)
        on = np.empty(theta.shape, dtype=bool)
        which = self.shape_of[live]
        for k, plant in enumerate(self.shapes):
            rows = which == k
            if rows.all():
                along, on = plant.track_coordinates(theta, xyz)
            elif rows.any():
                along[rows], on[rows] = plant.track_coordinates(theta[rows], xyz[rows])
        lost = self._lost[live]
        on[lost] = False
        on[~lost, 0] = True
        for j in np.flatnonzero(
            ~lost & ~on.all(axis=1)
        ).tolist():  # latched from the first step off the track
            i = int(live[j])
            first_off = int(np.flatnonzero(~on[j])[0])
            row = out[j, first_off - 1]
            self._lost[i] = True
            self._lost_time_s[i] = float(row[0])
            self.lost_state[i] = self.plants[i]._row_state(row)
            on[j, first_off:] = False
        self.last_row[live] = last
        self._time_s = float(last[0, 0])
        times = t0 + np.arange(m + 1) * self.dt  # as Plant.advance: its clock plus the step offsets
        return BatchBlock(times, along, theta, on)

    def _check_numerics(self, live: np.ndarray, t0: float, out: np.ndarray) -> None:
        """Plant._check_numerics for every live run: a NumericalError for the first run MuJoCo warned in
        (a simulation that warns stops stepping: its clock stops) or whose beam went past its stops further
        than they can yield."""
        # (lastinfo, number) per warning
        warned = np.flatnonzero(self.batch.warning[self.ids[live], :, 1].any(axis=1))
        theta = np.abs(out[:, :, self.theta_col])
        past = np.flatnonzero((theta > self.theta_limit_rad[live, None]).any(axis=1))
        if not (warned.size or past.size):
            return
        run = f"run {int(live[(warned if warned.size else past)[0]])}: " if self.n > 1 else ""
        if warned.size:
            j = int(warned[0])
            i = int(live[j])
            counts = dict(enumerate(self.batch.warning[self.ids[i], :, 1].tolist()))
            error = numerical_failure(
                self.plants[i].params, warning_text(counts), failure_time_s(np.r_[t0, out[j, :, 0]])
            )
        else:
            j = int(past[0])
            i = int(live[j])
            k = int(np.flatnonzero(theta[j] > self.theta_limit_rad[i])[0])
            error = beyond_stops(self.plants[i].params, float(theta[j, k]), float(out[j, k, 0]))
        raise type(error)(run + str(error))

    def true_state(self, runs: np.ndarray) -> np.ndarray:
        """Plant.state for runs ``runs``: from their last rows, a lost run's at the step it left the track."""
        states = np.empty((len(runs), 4))
        which = self.shape_of[runs]
        for k, plant in enumerate(self.shapes):
            rows = which == k
            if rows.all():
                states = plant.row_states(self.last_row[runs])
            elif rows.any():
                states[rows] = plant.row_states(self.last_row[runs[rows]])
        lost = self._lost[runs]
        states[lost] = self.lost_state[runs[lost]]  # Plant.state: the state at the step it left the track
        return states
