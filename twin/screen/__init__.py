"""The fast engine: the reference model's plant over many runs in a numba kernel (``twin.screen.plant``, every
equation compiled from its one home in the core: ``twin.reference``, ``twin.dcmotor``) under the batch engine's
own sensor chains, DAQ schedule, output stage and laws (``twin.rigs.batch.BatchRig`` over
``ReferenceBatchPhysics``, the reference backend's batch in ``twin.rigs.backends``, which
``run_batch(plant="reference")`` uses). ``twin.app.screening`` screens analyses with it and
confirms with MuJoCo. A rig with a part the kernel has no form for (``kernel_refusal``) is refused, naming it: the
commands then run it on MuJoCo alone (``twin.rigs.backends.engine_policy``)."""

from twin.screen.plant import (
    KERNEL_PARTS,
    PlantRows,
    ReferenceBatchPhysics,
    advance_plant,
    kernel_refusal,
    plant_rows,
)

__all__ = [
    "KERNEL_PARTS",
    "PlantRows",
    "ReferenceBatchPhysics",
    "advance_plant",
    "kernel_refusal",
    "plant_rows",
]
