"""The application layer: the ``ballbeam`` command (``twin.app.cli``, one module per command in
``twin.app.commands``), the analyses and the reports. It is the only part of ``twin`` that sees
``controllers`` and ``calib``; it hands the controller catalogue to the live view (twin.viewer) and the core
(the rest of ``twin``) never imports it (tests/test_layers.py).

The public surface (every other name is internal):

    SweepSettings, Grid, run_sweep              twin.app.sweep: a map of initial states (``ballbeam sweep``)
    write_sweep                                 twin.app.sweep_render: its JSON and map
    MonteCarloSettings, run_montecarlo,         twin.app.montecarlo: perturbed rigs (``ballbeam montecarlo``)
      load_spread
    run_robust                                  twin.app.robust: the robust region over many rigs
    ValidationCriteria, load_criteria           twin.app.validate: the validation battery (its entry point
                                                is ``twin.app.validate.validate``)
    BallBeamEnv, BallBeamVectorEnv              twin.app.envs: the Gymnasium environments (``BallBeam-v0``)

The names load on first use."""

from __future__ import annotations

from typing import TYPE_CHECKING

from twin.exports import lazy_exports

if TYPE_CHECKING:  # the names' real types for a type checker; at run time they load on first use (below)
    from twin.app.envs import BallBeamEnv, BallBeamVectorEnv
    from twin.app.montecarlo import MonteCarloSettings, load_spread, run_montecarlo
    from twin.app.robust import run_robust
    from twin.app.sweep import Grid, SweepSettings, run_sweep
    from twin.app.sweep_render import write_sweep
    from twin.app.validate import ValidationCriteria, load_criteria


__all__ = [
    "BallBeamEnv",
    "BallBeamVectorEnv",
    "Grid",
    "MonteCarloSettings",
    "SweepSettings",
    "ValidationCriteria",
    "load_criteria",
    "load_spread",
    "run_montecarlo",
    "run_robust",
    "run_sweep",
    "write_sweep",
]

_HOMES = {
    "Grid": "twin.app.sweep",
    "SweepSettings": "twin.app.sweep",
    "run_sweep": "twin.app.sweep",
    "write_sweep": "twin.app.sweep_render",
    "MonteCarloSettings": "twin.app.montecarlo",
    "load_spread": "twin.app.montecarlo",
    "run_montecarlo": "twin.app.montecarlo",
    "run_robust": "twin.app.robust",
    "ValidationCriteria": "twin.app.validate",
    "load_criteria": "twin.app.validate",
    "BallBeamEnv": "twin.app.envs",
    "BallBeamVectorEnv": "twin.app.envs",
}

__getattr__ = lazy_exports(__name__, _HOMES)
