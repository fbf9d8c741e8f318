"""The named data sets the pipeline and benchmarks use, each split into training and held-out
experiments."""

import functools
import hashlib
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import joblib
import numpy as np

from .._arrays import array_digest
from .._typing import Float2D
from .kuka import load_kuka
from .simulated import HURE_VASAK_THETAS, make_hure_vasak

if TYPE_CHECKING:
    from .user import DatasetRegistry


@dataclass(frozen=True)
class GroundTruth:
    """What a simulated data set knows about itself: the true PWARX structure and modes.

    Attributes
    ----------
    thetas : ndarray of shape (s, d, m)
        True parameter matrices, in the regressor order of eq. (3).
    modes_test : list of ndarrays of shape (N_e,)
        True mode (0-based) of every sample of each held-out experiment.
    na, nb : int
    affine : bool
        The true orders and constant term: estimates are comparable only with these.
    """

    thetas: np.ndarray
    modes_test: list[np.ndarray]
    na: int
    nb: int
    affine: bool


def with_unit(name: str, units: Mapping[str, str]) -> str:
    """``name [unit]`` for a channel or one of its lags, ``name`` alone without a unit.

    The channel of a regressor name such as ``q1(k-2)`` (:func:`~pwa_pipeline.regressors.regressor_names`)
    is the text before its ``(``; an empty unit counts as none.

    Examples
    --------
    >>> with_unit("q1(k-2)", {"q1": "deg"}), with_unit("y1", {})
    ('q1(k-2) [deg]', 'y1')
    """
    unit = units.get(name.split("(", 1)[0], "")
    return f"{name} [{unit}]" if unit else name


@dataclass(frozen=True)
class Dataset:
    """Training and held-out experiments of one data set, with channel names and units.

    Attributes
    ----------
    name : str
    u_train, y_train, u_test, y_test : lists of ndarrays of shape (N_e, r) or (N_e, m)
        One array per experiment.
    u_names, y_names : list of str
        Input and output channel names.
    truth : GroundTruth, optional
        A simulated data set's true system.
    units : dict of str to str
        The unit of each channel that has one (``{"q1": "deg"}``), for figure axes; a
        channel not in it (every channel of a simulated set) has none. Not part of
        :attr:`digest`: a unit names the numbers, it does not change them, so no model is
        fitted or scored again for it.
    """

    name: str
    u_train: list[Float2D]
    y_train: list[Float2D]
    u_test: list[Float2D]
    y_test: list[Float2D]
    u_names: list[str]
    y_names: list[str]
    truth: GroundTruth | None = None
    units: dict[str, str] = field(default_factory=dict)

    def __setstate__(self, state: dict) -> None:
        # a data set pickled before it had units (an older store) has none
        self.__dict__.update({"units": {}, **state})

    def label(self, name: str) -> str:
        """``name [unit]`` of one of its channels or their lags (:func:`with_unit`), for an
        axis label."""
        return with_unit(name, self.units)

    @functools.cached_property
    def digest(self) -> str:
        """Hash of the name, channel names, experiments and ground truth: what the
        pipeline's caches key on in place of the data, so that the arrays are hashed once
        per loaded data set, not at every cache lookup. The units are left out (see the
        class doc)."""
        parts = (self.u_train, self.y_train, self.u_test, self.y_test)
        h = hashlib.sha256(repr((self.name, self.u_names, self.y_names,
                                 [len(part) for part in parts])).encode())
        h.update(array_digest(*(a for part in parts for a in part)).encode())
        h.update(joblib.hash(self.truth).encode())
        return h.hexdigest()[:24]

    @property
    def n_train(self) -> int:
        """Training samples."""
        return sum(len(u) for u in self.u_train)

    @property
    def n_test(self) -> int:
        """Held-out samples."""
        return sum(len(u) for u in self.u_test)


DATASETS = ("hure_vasak", "kuka_robot")


def load_dataset(name: str, kuka_path: str | os.PathLike | None = None, seed: int = 0,
                 registry: "DatasetRegistry | None" = None) -> Dataset:
    """A named data set with its training and held-out parts.

    ``hure_vasak``: the section 5 system at 30 dB, N = 4000, ``seed`` for training and a fresh
    record (seed + 1000) for validation, with its :class:`GroundTruth`, unit-free.
    ``kuka_robot``: :func:`load_kuka` (train / test), joint positions in degrees and motor
    torques in N·m. Any other name: the user's data set of that name in
    ``registry`` (:class:`~pwa_pipeline.datasets.user.DatasetRegistry`).
    """
    if name == "hure_vasak":
        train, test = make_hure_vasak(seed=seed), make_hure_vasak(seed=seed + 1000)
        truth = GroundTruth(thetas=HURE_VASAK_THETAS.copy(), modes_test=[test.modes], na=1,
                            nb=1, affine=False)
        return Dataset(name, [train.u], [train.y], [test.u], [test.y], train.u_names,
                       train.y_names, truth)
    if name == "kuka_robot":
        r = load_kuka(kuka_path)
        return Dataset(name, r.u_train, r.y_train, r.u_test, r.y_test, r.u_names, r.y_names,
                       units=dict(r.units))
    if registry is not None and name in registry.names():
        return registry.get(name).load()
    known = list(DATASETS) + (registry.names() if registry is not None else [])
    raise ValueError(f"unknown data set {name!r}; known: {known}")
