"""The one data-set type every loader and generator returns ([`Dataset`][pwa_pipeline.datasets.Dataset]), and
what a simulated one knows about itself ([`GroundTruth`][pwa_pipeline.datasets.GroundTruth])."""

import functools
import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field

import joblib
import numpy as np

from .._arrays import array_digest
from .._typing import Float2D
from ..scoring.conventions import Convention


@dataclass(frozen=True)
class GroundTruth:
    """What a simulated data set knows about itself.

    Attributes
    ----------
    y_clean_train, y_clean_test : lists of ndarrays of shape (N_e, m)
        The outputs without measurement noise, one array per experiment.
    thetas : ndarray of shape (s, d, m), optional
        A PWARX system's true parameter matrices, in the regressor order of eq. (3).
    modes_train, modes_test : lists of ndarrays of shape (N_e,), optional
        A PWARX system's true mode (0-based) of every sample.
    na, nb : int, optional
    affine : bool, optional
        A PWARX system's true orders and constant term: estimates are comparable only with
        these.
    flags_train, flags_test : dict of str to lists of ndarrays of shape (N_e,) of bool
        A simulated machine's switching regimes per sample (e.g. ``"overflow"``).
    noise_std : ndarray of shape (m,), optional
        The measurement noise's standard deviation, in the outputs' units.
    """

    y_clean_train: list[Float2D]
    y_clean_test: list[Float2D] = field(default_factory=list)
    thetas: np.ndarray | None = None
    modes_train: list[np.ndarray] | None = None
    modes_test: list[np.ndarray] | None = None
    na: int | None = None
    nb: int | None = None
    affine: bool | None = None
    flags_train: dict[str, list[np.ndarray]] = field(default_factory=dict)
    flags_test: dict[str, list[np.ndarray]] = field(default_factory=dict)
    noise_std: np.ndarray | None = None


def with_unit(name: str, units: Mapping[str, str]) -> str:
    """``name [unit]`` for a channel or one of its lags, ``name`` alone without a unit.

    The channel of a regressor name such as ``q1(k-2)``
    (`regressor_names`) is the text before its ``(``; an empty
    unit counts as none.

    Examples
    --------
    >>> with_unit("q1(k-2)", {"q1": "deg"}), with_unit("y1", {})
    ('q1(k-2) [deg]', 'y1')
    """
    unit = units.get(name.split("(", 1)[0], "")
    return f"{name} [{unit}]" if unit else name


@dataclass(frozen=True)
class Dataset:
    """Training and held-out experiments of one data set, with channel names and units: what
    every loader and generator of `pwa_pipeline.datasets` returns, as scikit-learn's
    loaders all return a ``Bunch``.

    Every estimator takes the experiments as they are (``model.fit(data.u_train,
    data.y_train)``, ``evaluate(model, data.u_test, data.y_test)``): lists of arrays, one
    per experiment, so that no regressor spans two.

    Attributes
    ----------
    name : str
    u_train, y_train, u_test, y_test : lists of ndarrays of shape (N_e, r) or (N_e, m)
        One array per experiment; the held-out lists are empty when a generator was asked
        for no held-out experiment.
    u_names, y_names : list of str
        Input and output channel names.
    truth : GroundTruth, optional
        A simulated data set's true system, noise-free outputs and regimes.
    units : dict of str to str
        The unit of each channel that has one (``{"q1": "deg"}``), for figure axes; a
        channel not in it has none. Not part of [`digest`][pwa_pipeline.datasets.Dataset.digest]: a unit names
        the numbers, it does not change them, so no model is fitted or scored again for it.
    sample_time : float, optional
        Seconds between samples, when known.
    convention : Convention, optional
        A measured benchmark's own figure of merit on its held-out record (e.g. free-run
        RMSE in mm after 20 samples), scored beside this project's NRMSE.
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
    sample_time: float | None = None
    convention: Convention | None = None

    def __setstate__(self, state: dict) -> None:
        # a data set pickled before it had units (an older store) has none
        self.__dict__.update({"units": {}, "sample_time": None, "convention": None, **state})

    def label(self, name: str) -> str:
        """``name [unit]`` of one of its channels or their lags (`with_unit`), for an
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
