"""Data: the paper's simulated system, the KUKA KR300 robot, simulated machines with switching
physics, and users' own tables."""

from .kuka import RobotData, default_kuka_path, load_kuka
from .machines import (
    MACHINES,
    MachineData,
    make_dc_motor,
    make_machine,
    make_two_link_arm,
    make_two_tank,
)
from .registry import DATASETS, Dataset, GroundTruth, load_dataset
from .simulated import SimulatedPWA, make_hure_vasak
from .tables import load_table

__all__ = ["DATASETS", "MACHINES", "Dataset", "GroundTruth", "MachineData", "RobotData",
           "SimulatedPWA", "default_kuka_path", "load_dataset", "load_kuka", "load_table",
           "make_dc_motor", "make_hure_vasak", "make_machine", "make_two_link_arm",
           "make_two_tank"]
