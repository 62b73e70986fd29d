"""Calibration: fit the twin to a rig from the logs its software records.

The public surface (the implementation is in the modules named):

    load_rig_log(path) -> RigLog                       calib.logs: a data_file.mat or CSV, validated
    calibrate(logs, fit=[...], start=Parameters) -> Calibration
                                                       calib.identify: dynamic identification (windows
                                                       screened, adequacy and excitation judged:
                                                       Calibration.problems; calib.adequacy: the residuals)
    FITTABLE                                           the parameters it can fit, with their bounds
    load_table(path), calibrate_table(table)           calib.static: Table 6.3-style sensor tables
    calib.part_identify.calibrate_part_rig(serial_log, fit, start)
                                                       a part-built rig (servo, lever, VL53L0X) fitted to
                                                       its sketch's serial log (calib.serial_log)
    EXPERIMENTS, RECOMMENDED, run_experiment(name, params)
                                                       calib.experiments: what to record on a rig
    write_report(calibration, out_dir)                 calib.report: params.toml, calibration.json, report
    calib.compare.compare(logs, params)                the twin's prediction of recorded logs (ballbeam compare)
    CalibrationError, TableError                       what a log or table it cannot use raises, naming it

Every other name of the package's modules is internal and may change.
"""

from calib.experiments import EXPERIMENTS, RECOMMENDED, run_experiment
from calib.identify import FITTABLE, Calibration, CalibrationError, calibrate
from calib.logs import RigLog, load_rig_log, rig_log
from calib.report import write_report
from calib.static import TableError, load_table
from calib.static import calibrate as calibrate_table

__all__ = [
    "EXPERIMENTS",
    "FITTABLE",
    "RECOMMENDED",
    "Calibration",
    "CalibrationError",
    "RigLog",
    "TableError",
    "calibrate",
    "calibrate_table",
    "load_rig_log",
    "load_table",
    "rig_log",
    "run_experiment",
    "write_report",
]
