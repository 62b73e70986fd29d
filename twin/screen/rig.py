"""The fast engine's rig: the batch engine's rig (``twin.rigs.batch.BatchRig``: the sensor chains, the DAQ
schedule, the output stage and the recorder over a batch axis, the very functions a single run uses) with the
reference plant's physics in the compiled kernel (``twin.screen.plant``) instead of MuJoCo.

Each run is ``run_closed_loop(..., plant="reference")`` of the same start and seed bit for bit: the kernel
steps as ``ReferencePlant.advance`` (same operations in the same order), and the rest is the batch engine's,
which is each single rig's (``tests/test_screen.py``)."""

from __future__ import annotations

import numpy as np
from mujoco import batch as mjbatch

from twin.parameters import Parameters
from twin.physics import check_initial_state
from twin.plant import Plant
from twin.rigs.batch import BatchRig
from twin.screen.plant import PlantRows, advance_plant, plant_rows

__all__ = ["ReferenceBatchRig"]


class ReferenceBatchRig(BatchRig):
    """``BatchRig`` over the analytic reference plant (the physics of ``plant="reference"``), compiled."""

    def _start_physics(
        self,
        params: list[Parameters],
        x0: np.ndarray,
        theta0: np.ndarray,
        nthread: int,
        batch: mjbatch.Batch | None,
        ids: np.ndarray | None,
        plant_cache: dict[Parameters, Plant] | None,
    ) -> None:
        """As ``ReferencePlant.reset``: each start checked, at rest, the clock at 0."""
        if batch is not None:
            raise ValueError("the reference plant's runs are not rows of a MuJoCo batch")
        for i, q in enumerate(params):
            check_initial_state(q, float(x0[i]), float(theta0[i]), 0.0, 0.0)
        self.plant = plant_rows(params)
        self.states = np.zeros((len(params), 4))
        self.states[:, 0], self.states[:, 1] = x0, theta0
        self.lost_step = np.full(len(params), -1, dtype=np.int64)  # ≥ 0 once lost: the kernel skips the run
        self.physics_time_s = 0.0

    def _advance(self, volts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``ReferencePlant.advance`` for every live run: (times (m+1,), x, θ, on-track (live, m+1))."""
        live, m, h = self.live, volts.shape[1], self.dt
        t0 = self.physics_time_s
        every = len(live) == self.n
        plant = self.plant if every else PlantRows(self.plant.rows[live], self.plant.timestep_s)
        states, lost_step = self.states[live], self.lost_step[live]
        recorded = advance_plant(plant, states, lost_step, volts, record=True)
        assert recorded is not None
        along, theta = recorded
        if not np.isfinite(states).all():
            j = int(np.flatnonzero(~np.isfinite(states).all(axis=1))[0])
            raise FloatingPointError(
                f"run {int(live[j])}: reference model state is not finite by t = {t0 + m * h:.3f} s"
            )
        on = np.ones(along.shape, dtype=bool)
        was_lost = self.lost[live]
        on[was_lost] = False
        for j in np.flatnonzero(~was_lost & (lost_step >= 0)).tolist():
            i, k = int(live[j]), int(lost_step[j])
            self.lost[i] = True
            self.lost_time_s[i] = t0 + k * h  # ReferencePlant's: its clock plus the step's offset
            self.lost_state[i] = states[j]  # the state stays where the ball left the track
            on[j, k:] = False
        self.states[live], self.lost_step[live] = states, lost_step
        times = t0 + np.arange(m + 1) * h
        self.physics_time_s = float(times[-1])
        return times, along, theta, on

    def true_state(self) -> np.ndarray:
        """SimRig.true_state for every live run: the held start, or the kernel's state (frozen once lost)."""
        live = self.live
        if self.held_now:
            return self.held[live].copy()
        return self.states[live]
