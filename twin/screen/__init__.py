"""The compiled screening engine (issue: analyses at the physical limit): the reference model's equations over
many runs in numba kernels, every equation from its one home in the core (``twin.reference``,
``twin.dcmotor``), compiled rather than rewritten."""

from twin.screen.plant import PlantRows, advance_plant, plant_rows

__all__ = ["PlantRows", "advance_plant", "plant_rows"]
