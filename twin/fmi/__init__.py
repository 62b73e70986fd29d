"""The twin in FMI: the rig exported as a co-simulation unit (``export``; the unit's script is ``ballbeam_fmu``)."""
