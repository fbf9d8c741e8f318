"""Data: the paper's simulated system, the KUKA KR300 robot, and users' own tables."""

from .kuka import RobotData, default_kuka_path, load_kuka
from .registry import DATASETS, Dataset, GroundTruth, load_dataset
from .simulated import SimulatedPWA, make_hure_vasak
from .tables import load_table

__all__ = ["DATASETS", "Dataset", "GroundTruth", "RobotData", "SimulatedPWA", "default_kuka_path",
           "load_dataset", "load_kuka", "load_table", "make_hure_vasak"]
