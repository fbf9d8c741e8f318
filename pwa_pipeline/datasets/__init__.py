"""Data: the paper's simulated system, the KUKA KR300 robot, the cascaded tanks and EMPS
benchmarks, simulated machines with switching physics, and users' own tables, every one
returned as a [`Dataset`][pwa_pipeline.datasets.Dataset]."""

from .builtin import DATASETS, load_dataset
from .dataset import Dataset, GroundTruth
from .kuka import default_kuka_path, load_kuka
from .machines import MACHINES, make_dc_motor, make_machine, make_two_link_arm, make_two_tank
from .measured import EMPS, MEASURED, TANKS, load_cascaded_tanks, load_emps
from .simulated import make_hure_vasak
from .tables import load_table
from .user import UserDataset

__all__ = ["DATASETS", "EMPS", "MACHINES", "MEASURED", "TANKS", "Dataset", "GroundTruth",
           "UserDataset", "default_kuka_path", "load_cascaded_tanks", "load_dataset",
           "load_emps", "load_kuka", "load_table", "make_dc_motor",
           "make_hure_vasak", "make_machine", "make_two_link_arm", "make_two_tank"]
