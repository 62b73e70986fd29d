"""The fast engine: the reference model's plant over many runs in a numba kernel (``twin.screen.plant``, every
equation compiled from its one home in the core: ``twin.reference``, ``twin.dcmotor``) under the batch engine's
own sensor chains, DAQ schedule, output stage and laws (``twin.rigs.batch.BatchRig`` over
``ReferenceBatchPhysics``, the reference backend's batch in ``twin.rigs.backends``, which
``run_batch(plant="reference")`` uses). ``twin.app.screening`` screens analyses with it and
confirms with MuJoCo."""

from twin.screen.plant import PlantRows, ReferenceBatchPhysics, advance_plant, plant_rows

__all__ = ["PlantRows", "ReferenceBatchPhysics", "advance_plant", "plant_rows"]
